#pragma once
// Which read requests fetch every present signal: signals of one table are merged into
// contiguous blocks, so a typical map (x, T, ... in adjacent input registers) costs one
// transaction per cycle instead of one per signal.

#include <array>
#include <cstdint>
#include <vector>

#include "drivers/modbus/modbus_settings.hpp"
#include "drivers/modbus/register_map.hpp"

namespace scp::drivers::modbus {

// The Modbus limit for one "read registers" request (FC 3/4).
inline constexpr int kMaxRegistersPerRead = 125;

struct ReadBlock {
  Table table = Table::input;
  int address = 0;
  int count = 0;
  bool operator==(const ReadBlock&) const = default;
};

// Where a signal's registers land: blocks[block].regs[offset...].
struct SignalSlot {
  int block = -1;  // -1: signal not present
  int offset = 0;
};

struct ReadPlan {
  std::vector<ReadBlock> blocks;
  std::array<SignalSlot, kSignalCount> slots{};
};

// Groups the present signals per table (input blocks first, then holding), in address order.
// Two neighbours share a block when the registers between them number at most `max_gap` and the
// block stays within kMaxRegistersPerRead. Throws DriverError if two signals overlap (naming both).
ReadPlan plan_reads(const ModbusSettings& settings, int max_gap);

}  // namespace scp::drivers::modbus

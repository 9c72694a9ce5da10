#pragma once
// The loop's period budget: every transaction of a cycle may wait up to the response timeout,
// and a cycle must still end before the next deadline even when the DAQ stops answering. On a
// serial line the frames themselves take time and each request waits for t3.5 of silence first
// (docs/driver-modbus.md, "RTU timing").

#include <string>
#include <vector>

#include "drivers/modbus/modbus_settings.hpp"

namespace scp::drivers::modbus {

// Transactions one loop cycle costs: one per read block plus the voltage command write.
int transactions_per_cycle(const ModbusSettings& settings);

// What one cycle of the configured map costs on the line, in seconds (all 0 over TCP).
struct LineCycle {
  int transactions = 0;
  double silences_s = 0.0;          // t3.5 before every request
  double wire_s = 0.0;              // every request's and reply's characters
  double longest_exchange_s = 0.0;  // the longest request + reply (the slave's turnaround aside)
  // The longest request + its reply's first character: what response_timeout must cover (it
  // bounds the wait for that character; the rest of the reply follows within the cycle).
  double longest_first_byte_s = 0.0;
};
LineCycle line_cycle(const ModbusSettings& settings);

// Throws DriverError with the numbers and the remedies when response_timeout × transactions
// exceeds `period_s`.
void check_timing(const ModbusSettings& settings, double period_s);

// On a serial line, what the configured timing cannot deliver (each with the figures and the
// remedy; empty over TCP): a response timeout shorter than the longest transaction's frames, a
// cycle of frames and t3.5 silences longer than the period, or timeouts that fit the period only
// without the silences (a transaction that waits its whole timeout then leaves the next less than
// its own; the cycle never runs into the next period). Warnings, not errors: a pty pair carries
// frames without wire time, and the last costs only cycles that already fail.
std::vector<std::string> line_timing_warnings(const ModbusSettings& settings, double period_s);

}  // namespace scp::drivers::modbus

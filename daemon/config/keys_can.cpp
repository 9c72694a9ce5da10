#include "daemon/config/keys_can.hpp"

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace scp::config {
namespace {

using drivers::can::ByteOrder;
using drivers::can::CanSettings;
using drivers::can::CanSignal;
using drivers::can::HeartbeatPayload;

// intel and motorola are the DBC world's names for the same two orders.
constexpr NameTable<ByteOrder, 4> kByteOrders{{{ByteOrder::little_endian, "little_endian"},
                                               {ByteOrder::big_endian, "big_endian"},
                                               {ByteOrder::little_endian, "intel"},
                                               {ByteOrder::big_endian, "motorola"}}};
constexpr NameTable<HeartbeatPayload, 2> kPayloads{
    {{HeartbeatPayload::counter, "counter"}, {HeartbeatPayload::canopen, "canopen"}}};

// Declares the DBC layout of one signal; `def` gives the defaults (the simulated node's layout).
void declare_layout(Binder& b, CanSignal& sig, const CanSignal& def) {
  b.integer("frame_id", sig.frame_id, def.frame_id, 0, 0x1FFFFFFF,
            "CAN identifier (DBC BO_ id without the 0x80000000 extended flag)");
  b.boolean("extended", sig.extended, def.extended, "29-bit identifier (else 11-bit, ≤ 0x7FF)");
  b.integer("dlc", sig.dlc, def.dlc, 0, 64,
            "payload bytes of the frame: ≤ 8 for classic CAN; 12..64 only with fd: true");
  b.integer("start_bit", sig.start_bit, def.start_bit, 0, 511,
            "DBC start bit: the LSB for little_endian, the MSB for big_endian (DBC numbering)");
  b.integer("length_bits", sig.length_bits, def.length_bits, 1, 64, "signal length in bits");
  b.choice("byte_order", sig.byte_order, def.byte_order, kByteOrders,
           "little_endian = intel (DBC @1), big_endian = motorola (DBC @0)");
  b.boolean("signed", sig.is_signed, def.is_signed, "two's complement (DBC '-') or unsigned ('+')");
  b.number("scale", sig.scale, def.scale, -1e12, 1e12,
           "physical = raw · scale + offset, SI units (m, m/s, °C, V); DBC factor");
  b.number("offset", sig.offset, def.offset, -1e12, 1e12, "DBC offset");
}

}  // namespace

void declare_can_keys(Binder& can_section, CanSettings& out) {
  const CanSettings def = drivers::can::default_can_settings();
  can_section.text("interface", out.interface, def.interface,
                   "SocketCAN interface (`ip link show type can`), e.g. can0 or vcan0; fd:N uses "
                   "descriptor N inherited from the parent process (a socket carrying can_frame "
                   "records, e.g. one end of a socketpair)");
  can_section.boolean("fd", out.fd, def.fd,
                      "CAN FD (frames up to 64 bytes; the interface must "
                      "be configured with `fd on`)");
  can_section.integer("tx_full_fault_after", out.tx_full_fault_after, def.tx_full_fault_after, 1,
                      100000, "consecutive cycles with a full transmit queue before a fault");
  can_section.integer("max_frames_per_cycle", out.max_frames_per_cycle, def.max_frames_per_cycle, 1,
                      100000,
                      "bound on the frames read per cycle, so a flooded bus cannot stall the loop");
  can_section.number("read_wait_s", out.read_wait_s, def.read_wait_s, 0.0, 10.0,
                     "s read() may wait for a new value of every sensor signal; 0 (real time) "
                     "never waits. Set it (e.g. 1) for --offline runs against scp-simdaq "
                     "--lockstep, whose node answers each command with one period of frames");

  // Sub-binders stay alive until the cross-key checks, which fail on the offending one.
  std::vector<std::pair<std::string, Binder>> sections;
  static constexpr const char* kDocs[drivers::can::kSignalCount] = {
      "position x in m (required)", "velocity ẋ in m/s (optional; else estimated from x)",
      "temperature T in °C, absolute (required)", "voltage read back in V (optional)",
      ("the heater's current in A (optional; present: the refinement's thermal input is the "
       "measured power V·I)")};
  for (int i = 0; i < drivers::can::kSignalCount; ++i) {
    const std::string name = drivers::can::kSignalNames[i];
    Binder b = can_section.section(name, kDocs[i]);
    CanSignal& sig = *drivers::can::signal_at(out, i);
    const CanSignal& d = *drivers::can::signal_at(def, i);
    b.boolean("present", sig.present, d.present, "whether the DAQ sends this signal");
    declare_layout(b, sig, d);
    b.number("stale_timeout_s", sig.stale_timeout_s, d.stale_timeout_s, 1e-4, 60.0,
             "a value older than this faults the driver (\"CAN signal " + name + " stale\")");
    sections.emplace_back(name, std::move(b));
  }
  Binder cmd = can_section.section("command", "the frame carrying the voltage command (V)");
  declare_layout(cmd, out.command.signal, def.command.signal);
  out.command.signal.present = true;
  cmd.boolean("send_each_cycle", out.command.send_each_cycle, def.command.send_each_cycle,
              "send every cycle (a watchdog on the DAQ can then detect a dead daemon); false: "
              "only on change");
  sections.emplace_back("command", std::move(cmd));

  Binder hb = can_section.section(
      "heartbeat",
      "heartbeat frame for the DAQ's communication watchdog, the only protection when the daemon "
      "or the bus is dead (CANopen heartbeat producer; docs/driver-can.md)");
  {
    const drivers::can::CanHeartbeat& d = def.heartbeat;
    drivers::can::CanHeartbeat& h = out.heartbeat;
    hb.boolean("enabled", h.enabled, d.enabled,
               "send the heartbeat frame (configure the DAQ's watchdog / heartbeat consumer to "
               "set its outputs to 0 V when it stops)");
    hb.integer("frame_id", h.frame_id, d.frame_id, 0, 0x1FFFFFFF,
               "CAN identifier of the heartbeat; CANopen: 0x700 + node id (0x701..0x77F)");
    hb.boolean("extended", h.extended, d.extended, "29-bit identifier (else 11-bit, ≤ 0x7FF)");
    hb.number("period_ms", h.period_ms, d.period_ms, 0.0, 65535.0,
              "ms between heartbeats of loop time (CANopen producer heartbeat time 0x1017), "
              "sent after the command frame of the cycle it falls due in; keep the DAQ's "
              "timeout (consumer heartbeat time) at 2-3 x this and above a few loop periods");
    hb.choice("payload", h.payload, HeartbeatPayload::counter, kPayloads,
              "counter: one byte counting 0..255 (an alive counter); canopen: one byte 0x05 "
              "(NMT operational), what a CANopen heartbeat consumer expects");
  }
  sections.emplace_back("heartbeat", std::move(hb));

  if (can_section.is_template()) return;
  if (const auto problem = drivers::can::validate_can_settings(out)) {
    const std::string& key = problem->key;
    const auto dot = key.find('.');
    if (dot != std::string::npos) {
      for (auto& [name, b] : sections) {
        if (name == key.substr(0, dot)) b.fail(key.substr(dot + 1), problem->message);
      }
    }
    can_section.fail(key, problem->message);
  }
}

}  // namespace scp::config

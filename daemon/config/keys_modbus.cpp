#include "daemon/config/keys_modbus.hpp"

#include <array>
#include <cstdint>
#include <string>

#include "drivers/modbus/register_codec.hpp"
#include "drivers/modbus/register_map.hpp"

namespace scp::config {

namespace {

using drivers::modbus::CommandRegister;
using drivers::modbus::ModbusSettings;
using drivers::modbus::RegisterSignal;
using drivers::modbus::RegisterType;
using drivers::modbus::Table;
using drivers::modbus::WordOrder;

using drivers::modbus::Transport;

// The register types and tables by the names the driver gives them (register_codec.hpp).
template <class E, std::size_t N, class NameOf>
constexpr NameTable<E, N> named(const std::array<E, N>& values, NameOf name_of_value) {
  NameTable<E, N> table{};
  for (std::size_t i = 0; i < N; ++i) table[i] = {values[i], name_of_value(values[i]).data()};
  return table;
}
constexpr auto kRegisterTypes =
    named(std::array{RegisterType::int16, RegisterType::uint16, RegisterType::int32,
                     RegisterType::uint32, RegisterType::float32},
          [](RegisterType t) { return drivers::modbus::type_name(t); });
constexpr auto kTables = named(std::array{Table::input, Table::holding},
                               [](Table t) { return drivers::modbus::table_name(t); });
constexpr NameTable<WordOrder, 3> kWordOrders{
    {{WordOrder::none, "none"}, {WordOrder::ab, "ab"}, {WordOrder::ba, "ba"}}};
constexpr NameTable<Transport, 2> kTransports{{{Transport::tcp, "tcp"}, {Transport::rtu, "rtu"}}};

constexpr std::string_view kTypeDoc =
    "register type: int16|uint16 use one register, int32|uint32|float32 two";
constexpr std::string_view kOrderDoc =
    "for 32-bit types, which register holds the high word: ab = the lower address (Modbus "
    "convention), ba = the higher ('word-swapped'); required for 32-bit types";

// Declares type and word_order; for 32-bit types a missing word order is an error, because
// guessing it wrong turns 1.5 into 5.9e-39 without any other symptom.
void declare_format(Binder& b, RegisterType& type, WordOrder& order, RegisterType def_type,
                    bool written) {
  b.choice("type", type, def_type, kRegisterTypes, kTypeDoc);
  b.choice("word_order", order, WordOrder::none, kWordOrders, kOrderDoc);
  if (!written) {
    // The default map (the one scp-simdaq serves when given no map) is ab.
    if (order == WordOrder::none) order = WordOrder::ab;
    return;
  }
  if (drivers::modbus::register_count(type) == 2 && order == WordOrder::none) {
    // Point at a line the user wrote: the type if given, else any key of this entry.
    std::string_view at = "type";
    for (const std::string_view k : {"word_order", "type", "address", "table", "scale", "offset"}) {
      if (b.present(k)) {
        at = k;
        break;
      }
    }
    b.fail(at, std::string(drivers::modbus::type_name(type)) +
                   (b.present("type") ? "" : " (the default type)") +
                   " spans two registers: set word_order: ab (high word first, the Modbus "
                   "convention) or ba (word-swapped), as the device manual says");
  }
}

void declare_signal(Binder& signals, std::string_view name, std::string_view doc,
                    RegisterSignal& sig, bool required, bool any_signal_written) {
  const bool written = signals.present(name);
  Binder b = signals.section(name, doc);
  b.choice("table", sig.table, Table::input, kTables,
           "input registers (function 4) or holding registers (function 3)");
  b.integer(
      "address", sig.address, sig.address, 0, 65535,
      "0-based protocol address of the first register (manual's 30001/40001 minus that base)");
  declare_format(b, sig.type, sig.word_order, RegisterType::float32, written);
  b.number("scale", sig.scale, sig.scale, -1e12, 1e12,
           "engineering value = raw * scale + offset, in SI units (m, m/s, degC, V, A)");
  b.number("offset", sig.offset, sig.offset, -1e12, 1e12, "added after scaling");
  sig.present = required || written;
  if (written && sig.scale == 0.0)
    b.fail("scale", "must not be 0: every reading would be the offset");
  if (required && any_signal_written && !written) {
    signals.fail(name, "is required: the estimator needs x and temperature; give its register");
  }
  if (sig.present && sig.address + drivers::modbus::register_count(sig.type) - 1 > 65535) {
    b.fail("address", "the value's registers run past 65535");
  }
}

// The holding register(s) of the voltage command; 0 V must be writable (the safe state).
void declare_command(Binder& m, CommandRegister& c) {
  const bool written = m.present("command");
  Binder b = m.section("command", "holding register(s) the voltage command is written to");
  b.integer("address", c.address, 0, 0, 65535, "0-based holding register address");
  declare_format(b, c.type, c.word_order, RegisterType::float32, written);
  b.number("scale", c.scale, 1.0, -1e12, 1e12, "raw = (V - offset) / scale, rounded for integers");
  b.number("offset", c.offset, 0.0, -1e12, 1e12, "V subtracted before scaling");
  b.number("min", c.min_volts, 0.0, -1000.0, 1000.0, "lowest voltage the DAQ output accepts, V");
  b.number("max", c.max_volts, 10.0, -1000.0, 1000.0, "highest voltage the DAQ output accepts, V");
  std::string function;
  b.choice("function", function, "auto", {"auto", "6", "16"},
           "Modbus function of the write: auto = 6 (write single register) for a 16-bit "
           "command, 16 (write multiple registers) for a 32-bit one; 16 for devices that "
           "accept only function 16");
  c.function = function == "6" ? 6 : function == "16" ? 16 : 0;
  if (c.function == 6 && drivers::modbus::register_count(c.type) != 1) {
    b.fail("function", "function 6 writes one register, but command.type " +
                           std::string(drivers::modbus::type_name(c.type)) +
                           " spans two; use 16 or auto");
  }
  if (c.scale == 0.0) b.fail("scale", "must not be 0");
  if (c.max_volts < c.min_volts) b.fail("max", "must be at least command.min");
  if (c.min_volts > 0.0 || c.max_volts < 0.0) {
    b.fail(c.min_volts > 0.0 ? "min" : "max",
           "0 V must lie in [min, max]: the safe state writes 0 V");
  }
  std::array<std::uint16_t, 2> regs{};
  for (const double v : {c.min_volts, 0.0, c.max_volts}) {
    if (!drivers::modbus::encode_command(c, v, regs.data())) {
      b.fail(c.scale != 1.0 || c.offset != 0.0 ? "scale" : "type",
             std::to_string(v) + " V does not fit " +
                 std::string(drivers::modbus::type_name(c.type)) + " with scale " +
                 std::to_string(c.scale) + " and offset " + std::to_string(c.offset) +
                 "; change command.type, scale or min/max");
    }
  }
  if (c.address + drivers::modbus::register_count(c.type) - 1 > 65535) {
    b.fail("address", "the command's registers run past 65535");
  }
}

// Where the DAQ is: TCP host and port, or the RTU serial line.
void declare_link(Binder& m, ModbusSettings& out) {
  m.choice("transport", out.transport, Transport::tcp, kTransports,
           "Modbus TCP (Ethernet) or Modbus RTU (RS-485/RS-232 serial line)");
  {
    Binder tcp = m.section("tcp", "Modbus TCP connection (used when transport: tcp)");
    tcp.text("host", out.host, "127.0.0.1", "IP address or host name of the DAQ");
    tcp.integer("port", out.port, 1502, 1, 65535, "TCP port (502 is the Modbus standard)");
  }
  {
    Binder rtu = m.section("rtu", "Modbus RTU serial line (used when transport: rtu)");
    std::string parity;
    rtu.text("device", out.device, "/dev/ttyUSB0",
             "serial device; prefer a stable /dev/serial/by-id/... path");
    rtu.integer("baud", out.baud, 115200, 1200, 4000000, "bits per second");
    rtu.choice("parity", parity, "N", {"N", "E", "O"}, "none, even or odd (Modbus default: E)");
    rtu.integer("data_bits", out.data_bits, 8, 5, 8, "data bits per character (Modbus RTU: 8)");
    rtu.integer("stop_bits", out.stop_bits, 1, 1, 2,
                "stop bits (Modbus: 1 with parity, 2 without; many devices accept 1)");
    out.parity = parity.empty() ? 'N' : parity[0];
  }
}

}  // namespace

void declare_modbus_keys(Binder& m, ModbusSettings& out) {
  declare_link(m, out);
  m.integer(
      "unit_id", out.unit_id, 1, 0, 255,
      "Modbus unit (slave) id of the DAQ: 1-247 on RTU; TCP devices often ignore it or use 255");
  m.number("response_timeout", out.response_timeout_s, 0.0004, 0.0001, 10.0,
           "s a transaction may wait for its reply (on RTU: for its first byte, then for each "
           "later byte after the one before); times the transactions per cycle it must fit in "
           "loop.period");
  m.number("offline_response_timeout", out.offline_response_timeout_s, 1.0, 0.0001, 60.0,
           "s a transaction may wait in scp-estimatord --offline (lock-step runs have no period "
           "budget: a late reply there is a loaded machine, not a dead DAQ)");
  m.integer("max_consecutive_failures", out.max_consecutive_failures, 3, 0, 1000,
            "failed reads (or writes) in a row tolerated as 'no data' before the loop faults");
  {
    Binder rc = m.section("reconnect", "back-off of the reconnect thread after a lost link");
    rc.number("initial", out.reconnect_initial_s, 0.1, 0.001, 60.0,
              "s before the first reconnection attempt; doubled after each failed attempt");
    rc.number("max", out.reconnect_max_s, 5.0, 0.001, 3600.0,
              "s, the longest wait between attempts");
    if (out.reconnect_max_s < out.reconnect_initial_s) {
      rc.fail("max", "must be at least reconnect.initial");
    }
  }
  {
    Binder tm =
        m.section("timing", "when samples were taken and commands took effect (real-time runs)");
    tm.boolean("stamp", out.timing.stamp, true,
               "true: stamp each sample with when the DAQ sampled it and each command with when "
               "it landed (transaction clock + RTU wire time + the latencies below); false: the "
               "cycle's deadline, as if the link took no time (much less accurate, "
               "docs/numerics.md)");
    tm.number("input_latency", out.timing.input_latency_s, 0.0, -1.0, 1.0,
              "s the DAQ's sample is older than when the request reached it (ADC conversion or "
              "averaging, a register image refreshed on the DAQ's own cycle)");
    tm.number("output_latency", out.timing.output_latency_s, 0.0, -1.0, 1.0,
              "s the DAQ's output changes after the write request reached it (DAC update "
              "cycle)");
    tm.boolean("serial_line", out.timing.serial_line, false,
               "transport tcp to a TCP-to-RTU gateway: time each transaction as the serial line "
               "behind it (rtu.baud, parity, data_bits, stop_bits): its frames and the 3.5 "
               "characters of silence after each, which a command sent right after a read "
               "waits out on the line unseen (docs/driver-modbus.md, \"Time\")");
  }
  m.integer("max_read_gap", out.max_read_gap, 8, 0, 120,
            "unused registers read and discarded to fetch two signals in one request");
  {
    Binder wd = m.section("watchdog",
                          "heartbeat for the DAQ's communication watchdog, the only protection "
                          "when the daemon or the link is dead (docs/driver-modbus.md)");
    wd.integer("register", out.watchdog_register, -1, -1, 65535,
               "holding register written 0/1 alternately (function 6); -1 = no heartbeat");
    wd.integer("every_cycles", out.watchdog_every, 10, 1, 100000,
               "cycles between heartbeat writes; keep every_cycles x loop.period_s well below "
               "the DAQ's watchdog timeout");
  }

  if (out.transport == drivers::modbus::Transport::rtu && (out.unit_id < 1 || out.unit_id > 247)) {
    m.fail("unit_id", "on RTU the unit id must be 1-247 (0 is broadcast, which gets no reply)");
  }

  Binder signals = m.section(
      "signals", "register map of the measured signals (defaults: scp-simdaq's default map)");
  const bool any = signals.present("x") || signals.present("xdot") ||
                   signals.present("temperature") || signals.present("voltage") ||
                   signals.present("current");
  declare_signal(signals, "x", "length change of the actuator, m (required)", out.x, true, any);
  declare_signal(signals, "xdot", "velocity, m/s (optional; absent: the loop estimates it)",
                 out.xdot, false, any);
  declare_signal(signals, "temperature", "actuator temperature, degC absolute (required)",
                 out.temperature, true, any);
  declare_signal(signals, "voltage",
                 "read-back of the applied voltage, V (optional; absent: the last command)",
                 out.voltage, false, any);
  declare_signal(signals, "current",
                 "the heater's current, A (optional; present: the refinement's thermal input is "
                 "the measured power V*I)",
                 out.current, false, any);
  declare_command(m, out.command);
  if (const auto clash = drivers::modbus::find_overlap(out)) {
    const auto& [a, b] = *clash;
    // Name the later entry at its own line; "signals.x" is the key "x" of the signals section.
    constexpr std::string_view kPrefix = "signals.";
    const bool is_signal = b.name.substr(0, kPrefix.size()) == kPrefix;
    const Binder& at = is_signal ? signals : m;
    at.fail(is_signal ? b.name.substr(kPrefix.size()) : b.name,
            std::string(drivers::modbus::table_name(b.table)) + " registers " +
                std::to_string(b.first) + "-" + std::to_string(b.last) + " overlap " +
                std::string(a.name) + " (registers " + std::to_string(a.first) + "-" +
                std::to_string(a.last) + "); give each signal its own registers");
  }
}

}  // namespace scp::config

#pragma once
// Settings of the Modbus DAQ driver. Plain data: daemon/config/keys_modbus.cpp declares the YAML
// keys and fills this struct; the driver validates what the config layer cannot (timing).

#include <cstdint>
#include <string>

namespace scp::drivers::modbus {

enum class Transport : std::uint8_t { tcp, rtu };
enum class Table : std::uint8_t { input, holding };  // input registers (FC 4), holding (FC 3)
enum class RegisterType : std::uint8_t { int16, uint16, int32, uint32, float32 };
// Which 16-bit register carries the high word of a 32-bit value: ab = the first (lower address,
// "big-endian" word order, Modbus convention), ba = the second ("word-swapped"). Bytes inside a
// register are always big-endian on the wire; libmodbus already turns them into uint16_t.
enum class WordOrder : std::uint8_t { none, ab, ba };

// One measured quantity in the DAQ's register map. engineering value = raw · scale + offset.
struct RegisterSignal {
  bool present = false;
  Table table = Table::input;
  int address = 0;  // 0-based protocol address (a "30001"-style manual number minus 30001)
  RegisterType type = RegisterType::float32;
  WordOrder word_order = WordOrder::ab;
  double scale = 1.0;
  double offset = 0.0;
};

// The holding register(s) the voltage command is written to. raw = (V − offset) / scale, rounded
// for integer types and range-checked for the type.
struct CommandRegister {
  int address = 0;
  RegisterType type = RegisterType::float32;
  WordOrder word_order = WordOrder::ab;
  double scale = 1.0;
  double offset = 0.0;
  double min_volts = 0.0;  // the DAQ output's range; 0 V must lie inside (safe state)
  double max_volts = 10.0;
  // Modbus function used for the write: 0 = 6 for one register and 16 for two; 16 for a
  // one-register command on devices that accept only "write multiple registers".
  int function = 0;
};

// How samples and commands are placed in time on a real-time run (docs/driver-modbus.md, "Time").
struct LinkTiming {
  // true: Sample::t is when the DAQ sampled (the read transaction's time stamp, wire_time.hpp)
  // and Sample::voltage_since when the last command landed; false: the cycle's deadline and −∞,
  // as if the link took no time (offline and lock-step runs behave so anyway).
  bool stamp = true;
  double input_latency_s = 0.0;   // the DAQ's sample is this much older than the wire model says
  double output_latency_s = 0.0;  // its output changes this much later than the wire model says
  // Modbus TCP to a TCP-to-RTU gateway: the transactions are timed as the serial line behind it
  // (rtu.baud, parity, data and stop bits), its frames and its 3.5-character silences included.
  bool serial_line = false;
};

struct ModbusSettings {
  Transport transport = Transport::tcp;
  // tcp
  std::string host = "127.0.0.1";
  int port = 1502;
  // rtu
  std::string device = "/dev/ttyUSB0";
  int baud = 115200;
  char parity = 'N';  // 'N', 'E' or 'O'
  int data_bits = 8;
  int stop_bits = 1;

  int unit_id = 1;
  double response_timeout_s = 0.0004;  // per transaction; see check_timing()
  // An offline (lock-step) run has no wall-clock deadline: a late reply there is load on the
  // machine, not a dead DAQ. scp-estimatord --offline uses this timeout and skips check_timing().
  double offline_response_timeout_s = 1.0;
  // false only for offline (lock-step) runs: no period budget to check, and no inter-frame
  // silence kept on an RTU line (the lock-step simulator takes frames by their length, and a
  // silence in each of a run's many steps would only slow a run that has no wall clock).
  bool enforce_period_budget = true;
  int max_consecutive_failures = 3;  // failed transactions tolerated in a row
  double reconnect_initial_s = 0.1;  // back-off of the reconnect thread, doubled per attempt
  double reconnect_max_s = 5.0;
  int max_read_gap = 8;  // registers read and discarded to merge two signals into one request
  // Feeding the DAQ's communication watchdog (docs/driver-modbus.md): every watchdog_every
  // cycles the driver writes 0/1 alternately (function 6) to holding register watchdog_register
  // (-1 = off). When the daemon dies or the link is dead the writes stop and a DAQ configured
  // with a communication timeout sets its output to the safe value by itself.
  int watchdog_register = -1;
  int watchdog_every = 10;

  RegisterSignal x{true, Table::input, 0, RegisterType::float32, WordOrder::ab, 1.0, 0.0};
  RegisterSignal xdot{false, Table::input, 4, RegisterType::float32, WordOrder::ab, 1.0, 0.0};
  RegisterSignal temperature{true, Table::input, 2, RegisterType::float32, WordOrder::ab, 1.0, 0.0};
  RegisterSignal voltage{false, Table::input, 6, RegisterType::float32, WordOrder::ab, 1.0, 0.0};
  RegisterSignal current{false, Table::input, 8, RegisterType::float32, WordOrder::ab, 1.0, 0.0};
  CommandRegister command;
  LinkTiming timing;
};

}  // namespace scp::drivers::modbus

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
  bool enforce_period_budget = true;  // false only for offline runs
  int max_consecutive_failures = 3;   // failed transactions tolerated in a row
  double reconnect_initial_s = 0.1;   // back-off of the reconnect thread, doubled per attempt
  double reconnect_max_s = 5.0;
  int max_read_gap = 8;  // registers read and discarded to merge two signals into one request

  RegisterSignal x{true, Table::input, 0, RegisterType::float32, WordOrder::ab, 1.0, 0.0};
  RegisterSignal xdot{false, Table::input, 4, RegisterType::float32, WordOrder::ab, 1.0, 0.0};
  RegisterSignal temperature{true, Table::input, 2, RegisterType::float32, WordOrder::ab, 1.0, 0.0};
  RegisterSignal voltage{false, Table::input, 6, RegisterType::float32, WordOrder::ab, 1.0, 0.0};
  CommandRegister command;
};

}  // namespace scp::drivers::modbus

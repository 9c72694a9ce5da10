#pragma once
// Settings of the SocketCAN driver: where each quantity sits in which frame, described exactly as
// a DBC file describes a signal (start bit, length, byte order, sign, factor, offset).

#include <cstdint>
#include <optional>
#include <string>

namespace scp::drivers::can {

// DBC "@1" is Intel (little endian: start_bit is the least significant bit), "@0" is Motorola
// (big endian: start_bit is the most significant bit, in the DBC's "bit 7 of byte 0 is bit 7"
// numbering).
enum class ByteOrder : std::uint8_t { little_endian, big_endian };

struct CanSignal {
  bool present = false;
  std::uint32_t frame_id = 0;  // without CAN_EFF_FLAG
  bool extended = false;       // 29-bit identifier
  int dlc = 8;                 // payload bytes of the frame (0..8 classic; FD: up to 64)
  int start_bit = 0;
  int length_bits = 16;  // 1..64
  ByteOrder byte_order = ByteOrder::little_endian;
  bool is_signed = false;
  double scale = 1.0;  // physical = raw · scale + offset
  double offset = 0.0;
  double stale_timeout_s = 0.05;  // a sensor signal older than this faults the driver
};

// The frame the driver sends to command the actuator voltage (V).
// A heartbeat frame for the DAQ's communication watchdog: the only protection when the daemon or
// the bus link is dead (docs/driver-can.md). It follows the CANopen heartbeat producer (CiA 301:
// COB-ID 0x700 + node id, one data byte, period = "producer heartbeat time" 0x1017 in ms), so a
// DAQ configured as heartbeat consumer (0x1016) of that id drops its outputs when it stops.
enum class HeartbeatPayload : std::uint8_t {
  counter,  // one byte counting 0..255 and wrapping: an alive counter firmware can check
  canopen,  // one byte, NMT state 0x05 (operational), what a CANopen heartbeat consumer expects
};
struct CanHeartbeat {
  bool enabled = false;
  std::uint32_t frame_id = 0x77F;  // CANopen: 0x700 + the daemon's node id (127 here)
  bool extended = false;
  double period_ms = 100.0;  // ≤ 65535 (0x1017 is 16 bits); the DAQ's timeout must be longer
  HeartbeatPayload payload = HeartbeatPayload::counter;
};

struct CanCommand {
  CanSignal signal;             // layout of the voltage in the command frame (present is ignored)
  bool send_each_cycle = true;  // false: send only when the encoded value changes
};

struct CanSettings {
  std::string interface = "can0";
  bool fd = false;        // CAN FD (CAN_RAW_FD_FRAMES): frames up to 64 bytes
  CanSignal x;            // m, required
  CanSignal xdot;         // m/s, optional (absent: Sample::xdot = NaN)
  CanSignal temperature;  // °C absolute, required
  CanSignal voltage;      // V read back, optional (absent: the last command is reported)
  CanSignal current;      // A, the heater's current, optional (absent: Sample::current = NaN)
  CanCommand command;
  CanHeartbeat heartbeat;
  int tx_full_fault_after = 10;    // consecutive "transmit queue full" writes before a fault
  int max_frames_per_cycle = 256;  // bound on the per-cycle drain so a flooded bus cannot stall
  // > 0: read() waits up to this long for a new value of every sensor signal (lock-step offline
  // runs against scp-simdaq --lockstep); 0: never waits (real time: the node sends periodically).
  double read_wait_s = 0.0;
};

// The signal names, in the order the driver keeps them; used in messages and config keys.
inline constexpr int kSignalCount = 5;
inline constexpr const char* kSignalNames[kSignalCount] = {"x", "xdot", "temperature", "voltage",
                                                           "current"};

// Pointers to the sensor signals in kSignalNames order.
inline const CanSignal* signal_at(const CanSettings& s, int i) noexcept {
  const CanSignal* all[kSignalCount] = {&s.x, &s.xdot, &s.temperature, &s.voltage, &s.current};
  return all[i];
}
inline CanSignal* signal_at(CanSettings& s, int i) noexcept {
  CanSignal* all[kSignalCount] = {&s.x, &s.xdot, &s.temperature, &s.voltage, &s.current};
  return all[i];
}

// The first problem found in the settings: `key` is the config key relative to the can section
// ("x.start_bit"), `message` says what is wrong and what would be right.
struct SettingsProblem {
  std::string key;
  std::string message;
};

// Checks ranges and the cross-signal rules: identifiers within 11/29 bits, every signal inside its
// frame, signals of one frame agreeing on its length and not sharing bits, the command frame id
// distinct from every sensor frame id, x and temperature present, scale finite and non-zero.
std::optional<SettingsProblem> validate_can_settings(const CanSettings& s);

// A default layout that the example config, the simulated node and the tests share.
CanSettings default_can_settings();

}  // namespace scp::drivers::can

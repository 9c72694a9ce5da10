#include "drivers/can/can_settings.hpp"

#include <cmath>
#include <cstdio>
#include <string>

#include "drivers/can/signal_codec.hpp"

namespace scp::drivers::can {
namespace {

std::string hex_id(std::uint32_t id) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "0x%X", id);
  return buf;
}

bool valid_dlc(int dlc, bool fd) {
  if (dlc >= 0 && dlc <= 8) return true;
  if (!fd) return false;
  // CAN FD payloads come only in these lengths (ISO 11898-1:2015 DLC 9..15).
  for (int ok : {12, 16, 20, 24, 32, 48, 64}) {
    if (dlc == ok) return true;
  }
  return false;
}

std::optional<SettingsProblem> check_signal(const CanSignal& sig, const std::string& name,
                                            bool fd) {
  const std::string p = name + ".";
  const std::uint32_t max_id = sig.extended ? 0x1FFFFFFFU : 0x7FFU;
  if (sig.frame_id > max_id) {
    return SettingsProblem{p + "frame_id",
                           "frame id " + hex_id(sig.frame_id) + " does not fit " +
                               (sig.extended ? "29" : "11") + " bits (maximum " + hex_id(max_id) +
                               (sig.extended ? ")" : "); set extended: true for a 29-bit id")};
  }
  if (!valid_dlc(sig.dlc, fd)) {
    return SettingsProblem{p + "dlc", "frame length " + std::to_string(sig.dlc) +
                                          (fd ? " is not a CAN FD length (0-8, 12, 16, 20, 24, "
                                                "32, 48, 64)"
                                              : " exceeds 8 bytes; set fd: true for CAN FD")};
  }
  if (sig.length_bits < 1 || sig.length_bits > 64) {
    return SettingsProblem{p + "length_bits", "length_bits must be 1..64"};
  }
  if (sig.start_bit < 0 || !signal_fits(sig, static_cast<std::size_t>(sig.dlc))) {
    return SettingsProblem{
        p + "start_bit",
        "signal (start_bit " + std::to_string(sig.start_bit) + ", length_bits " +
            std::to_string(sig.length_bits) + ", " +
            (sig.byte_order == ByteOrder::little_endian ? "little_endian" : "big_endian") +
            ") does not fit a frame of " + std::to_string(sig.dlc) + " bytes (" +
            std::to_string(8 * sig.dlc) + " bits" + (fd ? ")" : "; 64 bits for classic CAN)")};
  }
  if (!std::isfinite(sig.scale) || sig.scale == 0.0) {
    return SettingsProblem{p + "scale", "scale must be finite and non-zero"};
  }
  if (!std::isfinite(sig.offset)) return SettingsProblem{p + "offset", "offset must be finite"};
  if (!(sig.stale_timeout_s > 0.0) || !std::isfinite(sig.stale_timeout_s)) {
    return SettingsProblem{p + "stale_timeout_s", "stale_timeout_s must be > 0"};
  }
  return std::nullopt;
}

bool same_frame(const CanSignal& a, const CanSignal& b) {
  return a.frame_id == b.frame_id && a.extended == b.extended;
}

}  // namespace

std::optional<SettingsProblem> validate_can_settings(const CanSettings& s) {
  if (s.interface.rfind("fd:", 0) == 0) {
    const std::string n = s.interface.substr(3);
    if (n.empty() || n.size() > 6 || n.find_first_not_of("0123456789") != std::string::npos) {
      return SettingsProblem{"interface",
                             "an inherited descriptor is written fd:N with N a number (fd:3)"};
    }
  }
  if (!(s.read_wait_s >= 0.0 && s.read_wait_s <= 10.0)) {
    return SettingsProblem{"read_wait_s", "must lie in 0..10 s"};
  }
  if (s.interface.empty() || s.interface.size() >= 16) {
    return SettingsProblem{"interface", "interface name must have 1..15 characters (e.g. can0)"};
  }
  if (!s.x.present) return SettingsProblem{"x.present", "the x signal is required"};
  if (!s.temperature.present) {
    return SettingsProblem{"temperature.present", "the temperature signal is required"};
  }
  for (int i = 0; i < kSignalCount; ++i) {
    const CanSignal& sig = *signal_at(s, i);
    if (!sig.present) continue;
    if (auto p = check_signal(sig, kSignalNames[i], s.fd)) return p;
  }
  if (auto p = check_signal(s.command.signal, "command", s.fd)) return p;
  for (int i = 0; i < kSignalCount; ++i) {
    const CanSignal& a = *signal_at(s, i);
    if (!a.present) continue;
    const std::string key = std::string(kSignalNames[i]) + ".frame_id";
    if (same_frame(a, s.command.signal)) {
      return SettingsProblem{key, "frame id " + hex_id(a.frame_id) +
                                      " is also the command frame id; the driver would read "
                                      "back its own commands. Use distinct ids"};
    }
    for (int j = 0; j < i; ++j) {
      const CanSignal& b = *signal_at(s, j);
      if (!b.present || !same_frame(a, b)) continue;
      if (a.dlc != b.dlc) {
        return SettingsProblem{std::string(kSignalNames[i]) + ".dlc",
                               "frame " + hex_id(a.frame_id) + " is given " +
                                   std::to_string(a.dlc) + " bytes here but " +
                                   std::to_string(b.dlc) + " bytes for signal " + kSignalNames[j]};
      }
      if (signals_overlap(a, b)) {
        return SettingsProblem{std::string(kSignalNames[i]) + ".start_bit",
                               "signals " + std::string(kSignalNames[j]) + " and " +
                                   kSignalNames[i] + " share bits in frame " + hex_id(a.frame_id)};
      }
    }
  }
  if (!(s.heartbeat.period_ms > 0.0) || !(s.heartbeat.period_ms <= 65535.0)) {
    return SettingsProblem{"heartbeat.period_ms",
                           "period_ms must lie in (0, 65535] ms (CANopen producer heartbeat "
                           "time); keep it well below the DAQ's watchdog timeout"};
  }
  if (s.heartbeat.enabled) {
    const CanHeartbeat& hb = s.heartbeat;
    const std::uint32_t max_id = hb.extended ? 0x1FFFFFFFU : 0x7FFU;
    if (hb.frame_id > max_id) {
      return SettingsProblem{"heartbeat.frame_id",
                             "frame id " + hex_id(hb.frame_id) + " does not fit " +
                                 (hb.extended ? "29" : "11") + " bits (maximum " + hex_id(max_id) +
                                 (hb.extended ? ")" : "); CANopen uses 0x700 + node id")};
    }
    const auto clash = [&](const CanSignal& sig) {
      return sig.frame_id == hb.frame_id && sig.extended == hb.extended;
    };
    if (clash(s.command.signal)) {
      return SettingsProblem{"heartbeat.frame_id", "frame id " + hex_id(hb.frame_id) +
                                                       " is also the command frame id; use "
                                                       "distinct ids"};
    }
    for (int i = 0; i < kSignalCount; ++i) {
      const CanSignal& sig = *signal_at(s, i);
      if (sig.present && clash(sig)) {
        return SettingsProblem{"heartbeat.frame_id", "frame id " + hex_id(hb.frame_id) +
                                                         " is also the frame of signal " +
                                                         kSignalNames[i] + "; use distinct ids"};
      }
    }
  }
  if (s.tx_full_fault_after < 1) {
    return SettingsProblem{"tx_full_fault_after", "tx_full_fault_after must be ≥ 1"};
  }
  if (s.max_frames_per_cycle < 1) {
    return SettingsProblem{"max_frames_per_cycle", "max_frames_per_cycle must be ≥ 1"};
  }
  return std::nullopt;
}

CanSettings default_can_settings() {
  CanSettings s;
  // Frame 0x101: position and velocity, 32-bit signed Intel (1 nm, 1 nm/s resolution).
  s.x = {true, 0x101, false, 8, 0, 32, ByteOrder::little_endian, true, 1e-9, 0.0, 0.05};
  s.xdot = {false, 0x101, false, 8, 32, 32, ByteOrder::little_endian, true, 1e-9, 0.0, 0.05};
  // Frame 0x102: temperature (0.1 m°C) and voltage read back (1 mV).
  s.temperature = {true, 0x102, false, 8, 0, 32, ByteOrder::little_endian, true, 1e-4, 0.0, 0.05};
  s.voltage = {false, 0x102, false, 8, 32, 16, ByteOrder::little_endian, false, 1e-3, 0.0, 0.05};
  // and the heater's current (1 mA, signed: ±32 A).
  s.current = {false, 0x102, false, 8, 48, 16, ByteOrder::little_endian, true, 1e-3, 0.0, 0.05};
  // Frame 0x201: the voltage command, 16-bit unsigned, 1 mV.
  s.command.signal = {true,  0x201, false, 2,   0, 16, ByteOrder::little_endian,
                      false, 1e-3,  0.0,   0.05};
  return s;
}

}  // namespace scp::drivers::can

#pragma once
// The configuration files the daemon and scp-simdaq share in these tests: the paper's plant and
// estimator (config/paper.yaml) behind a Modbus or CAN DAQ.

#include <cstdio>
#include <string>

namespace scp::test {

struct RunSetup {
  double period_s = 0.002;
  std::string socket_path;
  std::string state_dir;
  std::string sim_fault = "none";  // driver.sim.fault.kind of scp-simdaq's plant
  double sim_fault_start_s = 0.0;
  double recover_after_s = 2.0;
};

inline std::string common_yaml(const RunSetup& s) {
  return "loop:\n  period_s: " + std::to_string(s.period_s) +
         "\n  realtime: {required: false, lock_memory: false}\n"
         "actuator: {ambient_c: 25.0, mass_kg: 0.1, resistance_ohm: 1.0}\n"
         "estimator:\n  beta: 3.0\n  forgetting: 0.8\n  p0: 100.0\n  scale: [1, 1, 1, 1, 1, 1]\n"
         "  p_max: 1.0e+20\n  theta0: [0, 0, 0, 0, 0, 0]\n  voltage_hold: zoh\n"
         "excitation: {profile: paper}\n"
         "safety: {voltage_max_v: 3.3, temperature_max_c: 150.0, position_abs_max_m: 0.05, "
         "stale_timeout_s: 0.1, recover_after_s: " +
         std::to_string(s.recover_after_s) +
         "}\n"
         "socket: {path: \"" +
         s.socket_path + "\", group: \"\"}\nstate: {directory: \"" + s.state_dir +
         "\", warm_start: false, checkpoint_interval_s: 1000}\nlog_level: warn\n";
}

inline std::string sim_yaml(const RunSetup& s) {
  return "  sim:\n"
         "    plant: {m: 0.1, R: 1.0, Cth: 0.9090, lambda: 0.0540, b: 124.7, k: 181.3, "
         "alpha1: 0.08, alpha2: 0.01}\n"
         "    substeps: 20\n"
         "    noise: {x: 0, xdot: 0, temperature: 0, voltage: 0}\n"
         "    fault: {kind: " +
         s.sim_fault + ", start_s: " + std::to_string(s.sim_fault_start_s) + "}\n";
}

// signals: the YAML of driver.modbus.signals and command (indented by 4).
inline const std::string kFloat32Map =
    "    signals:\n"
    "      x:           {table: input, address: 0, type: float32, word_order: ab}\n"
    "      temperature: {table: input, address: 2, type: float32, word_order: ab}\n"
    "      xdot:        {table: input, address: 4, type: float32, word_order: ab}\n"
    "      voltage:     {table: input, address: 6, type: float32, word_order: ab}\n"
    "    command: {address: 0, type: float32, word_order: ab, min: 0, max: 10}\n";

// A coarse map a cheap DAQ might offer: 16-bit registers, 1 µm, 0.01 °C, 1 mV.
inline const std::string kInt16Map =
    "    signals:\n"
    "      x:           {table: input, address: 0, type: int16, scale: 1.0e-6}\n"
    "      temperature: {table: input, address: 1, type: int16, scale: 0.01}\n"
    "      voltage:     {table: input, address: 2, type: uint16, scale: 0.001}\n"
    "    command: {address: 0, type: uint16, scale: 0.001, min: 0, max: 10}\n";

inline std::string modbus_tcp_yaml(const RunSetup& s, int port,
                                   const std::string& map = kFloat32Map, double timeout = 0.001) {
  return common_yaml(s) + "driver:\n  type: modbus\n" + sim_yaml(s) +
         "  modbus:\n    transport: tcp\n    tcp: {host: 127.0.0.1, port: " + std::to_string(port) +
         "}\n    response_timeout: " + std::to_string(timeout) +
         "\n    reconnect: {initial: 0.05, max: 0.2}\n" + map;
}

inline std::string modbus_rtu_yaml(const RunSetup& s, const std::string& device,
                                   const std::string& map = kFloat32Map, double timeout = 0.001) {
  return common_yaml(s) + "driver:\n  type: modbus\n" + sim_yaml(s) +
         "  modbus:\n    transport: rtu\n    rtu: {device: \"" + device +
         "\", baud: 115200, parity: N, data_bits: 8, stop_bits: 1}\n    response_timeout: " +
         std::to_string(timeout) + "\n    reconnect: {initial: 0.05, max: 0.2}\n" + map;
}

// The daemon's side of a real-time Modbus RTU run over a socat pty pair at a 10 ms period. Each
// transaction passes four tty hops (daemon, socat, scp-simdaq) through the kernel's tty workqueue,
// which runs at ordinary priority whatever the peers' priority: on a busy machine a few replies in
// a row can miss the timeout. So 4 ms timeouts, and eight failures in a row (80 ms, below
// safety.stale_timeout_s) tolerated, as a lab would configure a slow serial link; a dead slave
// still faults within 80 ms.
inline std::string modbus_rtu_realtime_yaml(const RunSetup& s, const std::string& device) {
  return modbus_rtu_yaml(s, device, kFloat32Map + "    max_consecutive_failures: 8\n", 0.004);
}

// CAN: x and ẋ int32 in one frame, T and V read-back in another; fine scales (see the docs'
// quantization notes). read_wait_s > 0 for lock-step offline runs.
inline std::string can_yaml(const RunSetup& s, double read_wait_s, double x_scale = 1e-11,
                            double t_scale = 1e-6) {
  char xs[32], ts[32];
  std::snprintf(xs, sizeof xs, "%.3g", x_scale);
  std::snprintf(ts, sizeof ts, "%.3g", t_scale);
  std::string out =
      common_yaml(s) + "driver:\n  type: can\n" + sim_yaml(s) +
      "  can:\n    interface: \"fd:3\"\n    read_wait_s: " + std::to_string(read_wait_s) + "\n";
  out +=
      "    x: {present: true, frame_id: 0x101, dlc: 8, start_bit: 0, length_bits: 32, "
      "byte_order: little_endian, signed: true, scale: " +
      std::string(xs) + ", stale_timeout_s: 0.05}\n";
  out +=
      "    xdot: {present: true, frame_id: 0x101, dlc: 8, start_bit: 32, length_bits: 32, "
      "byte_order: little_endian, signed: true, scale: 1.0e-12, stale_timeout_s: 0.05}\n";
  out +=
      "    temperature: {present: true, frame_id: 0x102, dlc: 8, start_bit: 0, length_bits: "
      "32, byte_order: little_endian, signed: true, scale: " +
      std::string(ts) + ", stale_timeout_s: 0.05}\n";
  out +=
      "    voltage: {present: true, frame_id: 0x102, dlc: 8, start_bit: 32, length_bits: 32, "
      "byte_order: little_endian, signed: false, scale: 1.0e-6, stale_timeout_s: 0.05}\n";
  out +=
      "    command: {frame_id: 0x201, dlc: 4, start_bit: 0, length_bits: 32, byte_order: "
      "little_endian, signed: false, scale: 1.0e-6}\n";
  return out;
}

}  // namespace scp::test

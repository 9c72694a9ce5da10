#pragma once
// The simulated DAQ: drivers/sim's actuator advanced in real time and served over Modbus TCP or
// RTU with exactly the register map a ModbusSettings describes, so the daemon's Modbus driver
// (and any Modbus tool) sees what a real DAQ in front of an SCP would show.

#include <atomic>
#include <cstdint>
#include <string>

#include "drivers/modbus/modbus_settings.hpp"
#include "drivers/sample.hpp"
#include "drivers/sim/sim_settings.hpp"

struct _modbus_mapping_t;

namespace scp::drivers::simdaq {

struct SimDaqOptions {
  modbus::ModbusSettings map;  // transport, endpoint and register map
  sim::SimSettings sim;
  double period_s = 0.001;
  double fault_after_s = -1.0;      // ≥ 0: from then on requests are read and not answered
  double exception_after_s = -1.0;  // ≥ 0: from then on requests get exception replies
  int exception_code = 4;           // server device failure
  double fault_duration_s = -1.0;   // > 0: the fault/exception window ends after this long
  double duration_s = 0.0;          // > 0: exit after this long (tests)
  // Lock-step: the plant advances exactly one period each time the command register is written,
  // instead of with the wall clock, so an offline daemon runs the experiment as fast as the
  // transport allows (docs/simdaq.md).
  bool lockstep = false;
  // Wall-clock plant: integrated in continuous CLOCK_MONOTONIC time, sampled at the instant a
  // read request arrives and switched to a new command at the instant its write arrives (instead
  // of stepped on a period grid of its own). With `wire`, those instants and the replies are
  // those of an RTU line at map.baud/parity/stop bits (emulated_wire.hpp), whatever the transport.
  bool wallclock = false;
  bool wire = false;
  double wire_jitter_s = 0.0;  // each frame delayed by uniform [0, this] more
  double wire_gap_s = -1.0;    // inter-frame silence; < 0: 3.5 characters
  std::uint64_t wire_seed = 1;
  std::string command_log;  // non-empty: one line "step,wall_s,volts" per command received
  // Field faults of a real link: every late_every-th request (> 0) is answered late_factor ×
  // driver.modbus.response_timeout late, after the client has given up on it.
  int late_every = 0;
  double late_factor = 1.5;
  bool exception_reads_only = false;  // --exception-after answers reads only; writes work
  // A DAQ's communication watchdog (> 0): when it is not fed for this long the output falls to
  // 0 V. Fed by every write to holding register watchdog_register (≥ 0), or by any request.
  double watchdog_timeout_s = 0.0;
  int watchdog_register = -1;
};

// Whether a fault window that starts at `after` (< 0: never) and lasts `duration` (≤ 0: for
// ever) is open at time t.
inline bool in_window(double t, double after, double duration) noexcept {
  return after >= 0 && t >= after && (duration <= 0 || t < after + duration);
}

// Writes one sample into the register image (input/holding arrays of the mapping).
// Signals that are not present are skipped; NaN and inf go into float32 registers as such (a
// failed sensor); other values that do not fit their type are written as 0 — the caller counts
// them. Returns false when any present value did not fit.
bool encode_sample(const modbus::ModbusSettings& map, const Sample& sample,
                   std::uint16_t* input_registers, int n_input, std::uint16_t* holding_registers,
                   int n_holding) noexcept;

// The voltage the command register holds, clamped to [command.min, command.max]; 0 when it is
// not a finite number.
double decode_command(const modbus::CommandRegister& command,
                      const std::uint16_t* holding_registers) noexcept;

// Serves until `stop` is true (or duration_s elapsed). Prints one line
// "scp-simdaq: listening on HOST:PORT" (TCP, with the port actually bound when 0 was asked) or
// "scp-simdaq: serving DEVICE" (RTU) to stdout once ready. Returns the process exit code.
int serve_modbus(const SimDaqOptions& options, std::atomic<bool>& stop);

}  // namespace scp::drivers::simdaq

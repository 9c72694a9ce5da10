#pragma once
// The driver contract: how the loop talks to a device (simulated SCP, CSV replay, Modbus DAQ, CAN).
//
// Lifecycle (every driver):   constructed --open()--> opened --read/write...--> close()
//   open()          non-real-time. Connects, validates, allocates. Throws DriverError whose message
//                   names the remedy. After open() the output is 0 V, or (a device absent
//                   or silent at start) output_confirmed is false and the driver keeps trying
//                   to connect in the background, as after a link lost later.
//   read()          real-time, once per cycle. No allocation, no lock shared with non-real-time
//                   threads, no blocking beyond the device's own configured timeout.
//   write_voltage() real-time, once per cycle, with a value the safety layer already clamped.
//   safe_state()    real-time, best effort: command 0 V. Called on every fault and shutdown path;
//                   must be callable any number of times and after a failed read or write.
//                   Whether the device acknowledged it is in stats().output_confirmed.
//   A driver that loses its link tries 0 V on it before closing it, and sends 0 V first on a
//   new one, before any other command.
//   close()         non-real-time; leaves the device at 0 V.

#include <array>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>

#include "drivers/sample.hpp"

namespace scp::drivers {

// Raised by open() (and constructors) with a message a user can act on.
class DriverError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The loop's notion of "now", handed to each call: the cycle's deadline, not the wall clock, so a
// simulated device advances exactly one period per cycle both in real time and in batch runs.
struct CycleTime {
  double t = 0.0;       // s since the loop started (k · period)
  double period = 0.0;  // s
  // CLOCK_MONOTONIC ns of the deadline t stands for, in a real-time run; 0 in batch and lock-step
  // runs, which have no wall clock. A driver that time-stamps its transactions converts them to
  // loop time with it: t + (clock − deadline_ns)·1e-9 (Sample::t, Sample::voltage_since).
  std::int64_t deadline_ns = 0;
};

enum class IoStatus : std::uint8_t {
  ok,           // fresh data (read) / command accepted (write)
  no_data,      // nothing new this cycle; tolerated until the staleness limit
  end_of_data,  // a finite source (replay) is exhausted: the loop stops cleanly
  error,        // a failed transaction; reason says which
};

struct IoResult {
  IoStatus status = IoStatus::ok;
  // A static string (never allocated) naming what failed, for the fault reason.
  const char* reason = "";

  static constexpr IoResult ok() noexcept { return {}; }
  static constexpr IoResult fail(const char* why) noexcept { return {IoStatus::error, why}; }
};

// Counters a driver keeps for `status`; plain data so the loop can publish them lock-free.
struct DriverStats {
  std::uint64_t reads = 0;
  std::uint64_t read_errors = 0;
  std::uint64_t writes = 0;
  std::uint64_t write_errors = 0;
  std::uint64_t dropped = 0;     // frames or replies that arrived but could not be used
  std::uint64_t reconnects = 0;  // links re-established by the driver's own recovery
  // Replies that arrived after their transaction had timed out, recognised (Modbus TCP: by the
  // transaction id) and discarded instead of being taken for the answer to a later request.
  std::uint64_t late_replies = 0;
  // Samples and commands whose transaction took far longer than usual (the loop thread
  // preempted, a reply delivered late), so its midpoint no longer marks the device's event:
  // stamped from the cycle's deadline instead (drivers/modbus/stamp_gate.hpp). 0 when the driver
  // does not stamp.
  std::uint64_t stretched_stamps = 0;
  bool link_up = true;
  // The output as the device confirmed it, not as the loop wished it: the voltage of the last
  // command the device acknowledged, and whether the latest command (the 0 V of a safe state
  // included) was acknowledged. false: the device may still hold output_v, or whatever the
  // unacknowledged command set; only its own watchdog can bring it to 0 V (docs/driver-modbus.md).
  double output_v = 0.0;
  bool output_confirmed = true;
  // Why the latest transaction failed (a static string, "" when none failed yet): the service
  // logs it off the loop thread at debug level.
  const char* last_error = "";
};

class Driver {
 public:
  virtual ~Driver() = default;
  Driver() = default;
  Driver(const Driver&) = delete;
  Driver& operator=(const Driver&) = delete;

  virtual std::string_view name() const noexcept = 0;

  virtual void open() = 0;
  virtual IoResult read(const CycleTime& now, Sample& out) noexcept = 0;
  virtual IoResult write_voltage(double volts) noexcept = 0;
  virtual void safe_state() noexcept = 0;
  virtual void close() noexcept = 0;

  virtual DriverStats stats() const noexcept { return {}; }
  // Non-real-time (the service's thread): why the driver's background recovery last failed to
  // reach the device, for the log; "" when it has nothing to say.
  virtual std::string background_error() const { return {}; }

  // Whether the samples say when their voltage took effect (Sample::voltage_since): the daemon's
  // drivers do; a replayed file only with a V_since column. Without it, which interval a row's
  // voltage belongs to is not known (refine.voltage_interval `auto` estimates it then).
  virtual bool stamps_voltage_instants() const noexcept { return true; }

  // Only a simulated device knows the truth; real drivers keep the default.
  virtual bool true_theta(double /*t*/, std::array<double, 6>& /*theta*/) const noexcept {
    return false;
  }
};

}  // namespace scp::drivers

#pragma once
// The driver contract: how the loop talks to a device (simulated SCP, CSV replay, Modbus DAQ, CAN).
//
// Lifecycle (every driver):   constructed --open()--> opened --read/write...--> close()
//   open()          non-real-time. Connects, validates, allocates. Throws DriverError whose message
//                   names the remedy. After open() the output must already be 0 V.
//   read()          real-time, once per cycle. No allocation, no lock shared with non-real-time
//                   threads, no blocking beyond the device's own configured timeout.
//   write_voltage() real-time, once per cycle, with a value the safety layer already clamped.
//   safe_state()    real-time, best effort: command 0 V. Called on every fault and shutdown path;
//                   must be callable any number of times and after a failed read or write.
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
  bool link_up = true;
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

  // Only a simulated device knows the truth; real drivers keep the default.
  virtual bool true_theta(double /*t*/, std::array<double, 6>& /*theta*/) const noexcept {
    return false;
  }
};

}  // namespace scp::drivers

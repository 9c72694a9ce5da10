#pragma once
// A scriptable driver for the loop's tests: each read returns what the test put in `next`.

#include "drivers/driver.hpp"

namespace scp::daemon::testing {

class FakeDriver final : public drivers::Driver {
 public:
  std::string_view name() const noexcept override { return "fake"; }
  void open() override {}
  drivers::IoResult read(const drivers::CycleTime& now, drivers::Sample& out) noexcept override {
    if (status != drivers::IoStatus::ok) return {status, "fake read failure"};
    out = next;
    out.t = now.t;
    return {};
  }
  drivers::IoResult write_voltage(double volts) noexcept override {
    last_written = volts;
    ++writes;
    return {};
  }
  void safe_state() noexcept override {
    last_written = 0.0;
    ++safe_states;
  }
  void close() noexcept override {}

  drivers::Sample next{0.0, 0.0, 0.0, 25.0, 0.0};
  drivers::IoStatus status = drivers::IoStatus::ok;
  double last_written = -1.0;  // -1: nothing written yet
  int writes = 0;
  int safe_states = 0;
};

}  // namespace scp::daemon::testing

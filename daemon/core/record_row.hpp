#pragma once
// One row of a recording, pushed by the loop into an SPSC ring and written to CSV by the
// recorder thread (the loop never touches a file).

#include <array>
#include <cstdint>

#include "drivers/sample.hpp"

namespace scp::daemon {

// The sample the estimator was fed (its voltage_since recorded too, so that a replay of a link's
// run feeds the estimators the same instants), and what the loop made of it.
struct RecordRow : drivers::Sample {
  double voltage_command = 0.0;  // sent this cycle, held until the next
  std::array<double, 6> theta_hat{};
  std::array<double, 6> sigma{};
  std::array<double, 2> eps{};
  std::array<double, 2> af{};
  std::array<double, 2> af_hat{};
  std::uint8_t state = 0;
  std::int64_t unix_ns = 0;   // CLOCK_REALTIME of the cycle (0 when unknown)
  bool xdot_measured = true;  // false: ẋ estimated from x (driver.velocity)
  // Rows the loop dropped (ring full) before this one, since the start: the recorder marks the
  // place in the file, where a replay stops reproducing the live run.
  std::uint64_t dropped_before = 0;
};

}  // namespace scp::daemon

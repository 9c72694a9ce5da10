#pragma once
// The checks that protect the actuator. They read only the sample and the configured limits,
// never the estimator, so a diverging estimate can never switch a limit off.

#include <array>

#include "daemon/config/daemon_config.hpp"
#include "daemon/core/published_state.hpp"
#include "drivers/sample.hpp"

namespace scp::daemon {

using Reason = std::array<char, kReasonChars>;

// True when the sample is usable and within every limit. Otherwise false, with `reason` naming
// the signal, its value and the limit. `xdot_required` is false when ẋ is estimated from x;
// `current_required` true when the device measures the heater's current (Sample::current).
// Real-time safe (snprintf into the caller's buffer).
bool check_sample(const drivers::Sample& sample, const config::SafetySettings& limits,
                  bool xdot_required, bool current_required, Reason& reason) noexcept;

// The command actually sent: the excitation clamped to [0, voltage_max_v]; a non-finite request
// becomes 0 V.
double clamp_voltage(double requested, const config::SafetySettings& limits) noexcept;

void set_reason(Reason& reason, const char* text) noexcept;

// A sensor that has died often keeps repeating its last value instead of reporting an error. While
// a non-zero voltage is commanded the plant moves and a live sensor's x and T change at least in
// their last bits, so readings bit-identical for safety.stuck_timeout_s mean a stuck sensor.
// At 0 V a resting actuator may legitimately read constant values: the timer restarts.
class StuckDetector {
 public:
  // False (with `reason`) once x and T have been bit-identical for `timeout_s` of loop time while
  // `output_nonzero`. timeout_s ≤ 0 disables the check. Real-time safe.
  bool update(const drivers::Sample& sample, double t, bool output_nonzero, double timeout_s,
              Reason& reason) noexcept;
  void reset() noexcept { have_ = false; }

 private:
  bool have_ = false;
  double x_ = 0.0;
  double temperature_ = 0.0;
  double since_ = 0.0;  // loop time since which the reading has not changed
};

}  // namespace scp::daemon

#pragma once
// The checks that protect the actuator. They read only the sample and the configured limits,
// never the estimator, so a diverging estimate can never switch a limit off.

#include <array>

#include "daemon/config/daemon_config.hpp"
#include "daemon/published_state.hpp"
#include "drivers/sample.hpp"

namespace scp::daemon {

using Reason = std::array<char, kReasonChars>;

// True when the sample is usable and within every limit. Otherwise false, with `reason` naming
// the signal, its value and the limit. `xdot_required` is false when ẋ is estimated from x.
// Real-time safe (snprintf into the caller's buffer).
bool check_sample(const drivers::Sample& sample, const config::SafetySettings& limits,
                  bool xdot_required, Reason& reason) noexcept;

// The command actually sent: the excitation clamped to [0, voltage_max_v]; a non-finite request
// becomes 0 V.
double clamp_voltage(double requested, const config::SafetySettings& limits) noexcept;

void set_reason(Reason& reason, const char* text) noexcept;

}  // namespace scp::daemon

#include "daemon/core/safety.hpp"

#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>

namespace scp::daemon {

void set_reason(Reason& reason, const char* text) noexcept {
  const std::size_t n = std::strlen(text);
  if (n < reason.size()) {
    std::memcpy(reason.data(), text, n + 1);
    return;
  }
  // Too long for the fixed buffer: cut at a word boundary and say so, never mid-word.
  constexpr char kCut[] = " [...]";
  std::size_t keep = reason.size() - sizeof kCut;
  while (keep > 0 && text[keep] != ' ') --keep;
  if (keep == 0) keep = reason.size() - sizeof kCut;
  std::memcpy(reason.data(), text, keep);
  std::memcpy(reason.data() + keep, kCut, sizeof kCut);
}

namespace {

// The heater's current, where the device measures it: finite and within safety.current_max_a.
bool check_current(const drivers::Sample& s, const config::SafetySettings& limits,
                   Reason& reason) noexcept {
  if (!std::isfinite(s.current)) {
    set_reason(reason, "sensor fault: heater current is not a finite number");
    return false;
  }
  if (std::fabs(s.current) > limits.current_max_a) {
    std::snprintf(reason.data(), reason.size(),
                  "heater current |I| = %.4g A above safety.current_max_a = %.4g A (a short "
                  "circuit, or the current's scale in the driver's map)",
                  std::fabs(s.current), limits.current_max_a);
    return false;
  }
  return true;
}

}  // namespace

bool check_sample(const drivers::Sample& s, const config::SafetySettings& limits,
                  bool xdot_required, bool current_required, Reason& reason) noexcept {
  if (!std::isfinite(s.x)) {
    set_reason(reason, "sensor fault: position x is not a finite number");
    return false;
  }
  if (!std::isfinite(s.temperature)) {
    set_reason(reason, "sensor fault: temperature is not a finite number");
    return false;
  }
  if (!std::isfinite(s.voltage)) {
    set_reason(reason, "sensor fault: voltage read-back is not a finite number");
    return false;
  }
  if (xdot_required && !std::isfinite(s.xdot)) {
    set_reason(reason, "sensor fault: velocity xdot is not a finite number");
    return false;
  }
  if (current_required && !check_current(s, limits, reason)) return false;
  if (s.temperature > limits.temperature_max_c) {
    std::snprintf(reason.data(), reason.size(),
                  "temperature %.2f °C above safety.temperature_max_c = %.2f °C", s.temperature,
                  limits.temperature_max_c);
    return false;
  }
  if (s.temperature < limits.temperature_min_c) {
    std::snprintf(reason.data(), reason.size(),
                  "temperature %.2f °C below safety.temperature_min_c = %.2f °C (sensor broken?)",
                  s.temperature, limits.temperature_min_c);
    return false;
  }
  if (std::fabs(s.x) > limits.position_abs_max_m) {
    std::snprintf(reason.data(), reason.size(),
                  "position |x| = %.6g m above safety.position_abs_max_m = %.6g m", std::fabs(s.x),
                  limits.position_abs_max_m);
    return false;
  }
  // A read-back a little above the command is quantization or noise; far above it is a wiring
  // or DAC fault that the clamp on the command cannot fix.
  const double voltage_tolerance = 0.05 * limits.voltage_max_v + 0.05;
  if (s.voltage > limits.voltage_max_v + voltage_tolerance) {
    std::snprintf(reason.data(), reason.size(),
                  "voltage read back %.3f V above safety.voltage_max_v = %.3f V", s.voltage,
                  limits.voltage_max_v);
    return false;
  }
  return true;
}

double clamp_voltage(double requested, const config::SafetySettings& limits) noexcept {
  if (!std::isfinite(requested) || requested <= 0.0) return 0.0;
  return requested > limits.voltage_max_v ? limits.voltage_max_v : requested;
}

bool StuckDetector::update(const drivers::Sample& s, double t, bool output_nonzero,
                           double timeout_s, Reason& reason) noexcept {
  if (!(timeout_s > 0.0)) return true;
  // Bit patterns, not ==: a sensor toggling between 0.0 and -0.0 or repeating NaN is stuck too.
  const bool same =
      have_ && std::bit_cast<std::uint64_t>(s.x) == std::bit_cast<std::uint64_t>(x_) &&
      std::bit_cast<std::uint64_t>(s.temperature) == std::bit_cast<std::uint64_t>(temperature_);
  if (!same || !output_nonzero) {
    have_ = true;
    x_ = s.x;
    temperature_ = s.temperature;
    since_ = t;
    return true;
  }
  if (t - since_ < timeout_s) return true;
  std::snprintf(reason.data(), reason.size(),
                "sensor stuck: x and T unchanged for %.3g s with the output on "
                "(safety.stuck_timeout_s = %.3g s)",
                t - since_, timeout_s);
  return false;
}

}  // namespace scp::daemon

#include "refine/voltage_switches.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace scp::refine {

namespace {

double slope_into(std::span<const WindowSample> w, std::size_t k) noexcept {
  return (w[k].voltage - w[k - 1].voltage) / (w[k].t - w[k - 1].t);
}

// The step a switch must exceed: a hundredth of the voltage's range, or ten times the step's
// noise. For white noise σ_V a step has σ √2·σ_V and a second difference √6·σ_V; the median of
// the absolute second differences over 0.6745 is their σ, switches and all (they are few).
double switch_floor(std::span<const WindowSample> w) {
  double lo = w.front().voltage, hi = lo;
  std::vector<double> second;
  second.reserve(w.size());
  for (std::size_t k = 0; k < w.size(); ++k) {
    lo = std::min(lo, w[k].voltage);
    hi = std::max(hi, w[k].voltage);
    if (k >= 2)
      second.push_back(std::abs(w[k].voltage - 2.0 * w[k - 1].voltage + w[k - 2].voltage));
  }
  double step_noise = 0.0;
  if (!second.empty()) {
    const auto mid = second.begin() + static_cast<std::ptrdiff_t>(second.size() / 2);
    std::nth_element(second.begin(), mid, second.end());
    step_noise = *mid / 0.6745 * std::sqrt(2.0 / 6.0);
  }
  return std::max(0.01 * (hi - lo), 10.0 * step_noise);
}

// The chord's slope of interval k where it is one of the voltage's continuous stretches (not a
// switch, not a gap, inside the window); 0 otherwise, which holds that side of a switch flat.
double chord_slope(std::span<const WindowSample> w, std::size_t k,
                   const std::vector<bool>& switched) noexcept {
  if (k < 1 || k >= w.size() || switched[k] || !(w[k].t > w[k - 1].t)) return 0.0;
  return slope_into(w, k);
}

}  // namespace

std::vector<bool> find_voltage_switches(std::span<const WindowSample> w) {
  std::vector<bool> out(w.size(), false);
  if (w.size() < 3) return out;
  const double floor = switch_floor(w);
  if (!(floor > 0.0)) return out;
  for (std::size_t k = 1; k < w.size(); ++k) {
    if (!(w[k].t > w[k - 1].t)) continue;
    if (!(std::abs(w[k].voltage - w[k - 1].voltage) > floor)) continue;
    double neighbours = 0.0;
    if (k >= 2 && w[k - 1].t > w[k - 2].t) neighbours = std::abs(slope_into(w, k - 1));
    if (k + 1 < w.size() && w[k + 1].t > w[k].t)
      neighbours = std::max(neighbours, std::abs(slope_into(w, k + 1)));
    out[k] = std::abs(slope_into(w, k)) > kSwitchSlopeRatio * neighbours;
  }
  return out;
}

std::size_t hold_voltage_switches(std::span<WindowSample> w, double phase) {
  const std::vector<bool> switched = find_voltage_switches(w);
  std::size_t held = 0;
  for (std::size_t k = 1; k < w.size(); ++k) {
    if (switched[k]) {
      w[k].voltage_ramp = false;
      w[k].voltage_mid = std::numeric_limits<double>::quiet_NaN();
      w[k].voltage_since = w[k - 1].t + phase * (w[k].t - w[k - 1].t);
      w[k].slope_before = chord_slope(w, k - 1, switched);
      w[k].slope_after = chord_slope(w, k + 1, switched);
      ++held;
    } else if (switched[k - 1] || (k + 1 < w.size() && switched[k + 1])) {
      w[k].voltage_mid = std::numeric_limits<double>::quiet_NaN();
    }
  }
  return held;
}

std::size_t count_voltage_switches(std::span<const WindowSample> w) noexcept {
  std::size_t held = 0;
  for (std::size_t k = 1; k < w.size(); ++k) held += w[k].voltage_ramp ? 0 : 1;
  return held;
}

}  // namespace scp::refine

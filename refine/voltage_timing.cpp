#include "refine/voltage_timing.hpp"

#include <cmath>
#include <limits>

#include "refine/stages.hpp"

namespace scp::refine {

std::span<const WindowSample> prepare_window(std::span<const WindowSample> window,
                                             estimator::VoltageHold hold, VoltageInterval interval,
                                             std::vector<WindowSample>& storage,
                                             VoltageShape shape) {
  if (reads_as_recorded(hold, interval) || window.empty()) return window;
  storage.assign(window.begin(), window.end());
  for (std::size_t k = 1; k < window.size(); ++k)
    storage[k] = prepared_sample(window[k - 1], window[k], hold, interval);
  if (hold == estimator::VoltageHold::foh && shape == VoltageShape::smooth)
    add_cubic_midpoints(storage);
  return storage;
}

void add_cubic_midpoints(std::span<WindowSample> w) noexcept {
  for (std::size_t k = 2; k + 1 < w.size(); ++k) {
    const double h = w[k].t - w[k - 1].t;
    const double tolerance = 1e-6 * h;
    if (!(std::abs(w[k - 1].t - w[k - 2].t - h) <= tolerance) ||
        !(std::abs(w[k + 1].t - w[k].t - h) <= tolerance))
      continue;
    // The cubic through the four rows around the interval, at its middle.
    w[k].voltage_mid =
        (9.0 * (w[k - 1].voltage + w[k].voltage) - (w[k - 2].voltage + w[k + 1].voltage)) / 16.0;
  }
}

WindowSample prepared_sample(const WindowSample& prev, const WindowSample& cur,
                             estimator::VoltageHold hold, VoltageInterval interval) noexcept {
  WindowSample out = cur;
  if (interval == VoltageInterval::after) {
    out.voltage = prev.voltage;
    out.voltage_since = prev.t;
  }
  if (hold == estimator::VoltageHold::foh) out.voltage_ramp = true;
  return out;
}

namespace {

// T̄'s residual variance after the thermal stage on `window`; ∞ when it cannot be fitted.
double thermal_residual(std::span<const WindowSample> window, const Vector6& theta_start,
                        const FitSettings& settings) {
  FitState state;
  state.p = start_point(window, theta_start, settings.known);
  if (!state.p.allFinite()) return std::numeric_limits<double>::infinity();
  FitContext ctx(window, settings);
  if (fit_thermal(ctx, state) != StopReason::none) return std::numeric_limits<double>::infinity();
  return state.noise.tbar;
}

}  // namespace

VoltageInterval choose_voltage_interval(std::span<const WindowSample> window,
                                        const Vector6& theta_start, const FitSettings& settings) {
  std::vector<WindowSample> storage;
  const double before =
      thermal_residual(prepare_window(window, settings.voltage_hold, VoltageInterval::before,
                                      storage, settings.voltage_shape),
                       theta_start, settings);
  const double after =
      thermal_residual(prepare_window(window, settings.voltage_hold, VoltageInterval::after,
                                      storage, settings.voltage_shape),
                       theta_start, settings);
  return after < before ? VoltageInterval::after : VoltageInterval::before;
}

}  // namespace scp::refine

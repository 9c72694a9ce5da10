#include "refine/voltage_timing.hpp"

#include <cmath>
#include <limits>

#include "refine/heater_power.hpp"
#include "refine/stages.hpp"

namespace scp::refine {

std::span<const WindowSample> prepare_window(std::span<const WindowSample> window,
                                             estimator::VoltageHold hold, VoltageInterval interval,
                                             std::vector<WindowSample>& storage,
                                             VoltageShape shape) {
  const bool power = measures_current(window);
  if ((reads_as_recorded(hold, interval) && !power) || window.empty()) return window;
  storage.assign(window.begin(), window.end());
  for (std::size_t k = 1; k < window.size(); ++k)
    storage[k] = prepared_sample(window[k - 1], window[k], hold, interval);
  if (power) {
    // Each row's voltage is now the one that drove its current (refine/heater_power.hpp).
    use_measured_power(storage, reference_resistance(window, interval));
  }
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

// Schwarz's criterion of that fit on T̄ alone: n·ln σ̂² + k·ln n, k its free slots.
double thermal_criterion(std::span<const WindowSample> window, const Vector6& theta_start,
                         const FitSettings& settings) {
  const double variance = thermal_residual(window, theta_start, settings);
  if (!std::isfinite(variance) || !(variance > 0.0)) return std::numeric_limits<double>::infinity();
  int k = 0;
  for (const bool f : thermal_slots(settings)) k += f ? 1 : 0;
  const double n = static_cast<double>(window.size());
  return n * std::log(variance) + k * std::log(n);
}

}  // namespace

VoltageInterval choose_voltage_interval(std::span<const WindowSample> window,
                                        const Vector6& theta_start, const FitSettings& settings) {
  // A one-period shift of the voltage and a first-order lag of the sensor look alike in T̄ (to
  // O(Δ·τs·T̄'')): with the lag free, `after` with a lag of minus one period fits a record logged
  // `before` about as well, and `before` with a lag of one period one logged `after`. So an
  // estimated lag is also tried held at 0, and the criterion, which charges the lag its
  // parameter, prefers the interval that needs none; a real lag (tenths of a second) leaves both
  // held fits far behind and the free ones apart by its larger second-order term.
  FitSettings held = settings;
  if (!held.nuisance.sensor_lag.fixed) held.nuisance.sensor_lag = {.fixed = true, .value = 0.0};
  std::vector<WindowSample> storage;
  double best = std::numeric_limits<double>::infinity();
  VoltageInterval chosen = VoltageInterval::before;
  for (const VoltageInterval interval : {VoltageInterval::before, VoltageInterval::after}) {
    const std::span<const WindowSample> prepared =
        prepare_window(window, settings.voltage_hold, interval, storage, settings.voltage_shape);
    for (const FitSettings* s : {static_cast<const FitSettings*>(&held), &settings}) {
      if (s == &settings && settings.nuisance.sensor_lag.fixed) continue;  // tried as `held`
      const double score = thermal_criterion(prepared, theta_start, *s);
      if (score < best) {
        best = score;
        chosen = interval;
      }
    }
  }
  return chosen;
}

}  // namespace scp::refine

#include "refine/voltage_timing.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <optional>
#include <utility>

#include "refine/heater_power.hpp"
#include "refine/stages.hpp"

namespace scp::refine {

std::span<const WindowSample> prepare_window(std::span<const WindowSample> window,
                                             estimator::VoltageHold hold, VoltageInterval interval,
                                             std::vector<WindowSample>& storage, VoltageShape shape,
                                             double switch_phase) {
  const bool power = measures_current(window);
  if ((reads_as_recorded(hold, interval) && !power) || window.empty()) return window;
  storage.assign(window.begin(), window.end());
  for (std::size_t k = 1; k < window.size(); ++k)
    storage[k] = prepared_sample(window[k - 1], window[k], hold, interval);
  if (power) {
    // Each row's voltage is now the one that drove its current (refine/heater_power.hpp).
    use_measured_power(storage, reference_resistance(window, interval));
  }
  if (hold == estimator::VoltageHold::foh && shape == VoltageShape::smooth) {
    add_cubic_midpoints(storage);
    hold_voltage_switches(storage, switch_phase);
  }
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

// The thermal stage's fit (θ5, θ6, T̄0 on T̄ alone) judged by Schwarz's criterion,
// n·ln σ̂² + k·ln n with k its free slots (∞ when it cannot be fitted), the sensor lag it
// estimated and where it ended.
struct ThermalCriterion {
  double score = std::numeric_limits<double>::infinity();
  double lag = 0.0;
  std::optional<ParamVector> solution;
};

// Where a candidate's thermal fit starts: where `from` ended (the free lag's fit from the held
// lag's at the same timing: its lag 0 is where an estimated lag starts, and one pass less), else
// the fit's own start; the nuisance terms held where `settings` hold them.
ParamVector thermal_start(std::span<const WindowSample> window, const Vector6& theta_start,
                          const FitSettings& settings, const ThermalCriterion* from = nullptr) {
  ParamVector p = from != nullptr && from->solution
                      ? *from->solution
                      : start_point(window, theta_start, settings.known);
  const NuisanceSettings& n = settings.nuisance;
  for (const auto& [slot, setting] :
       {std::pair{kXZeroSlot, n.x_zero}, std::pair{kAmbientOffsetSlot, n.ambient_offset},
        std::pair{kAmbientDriftSlot, n.ambient_drift}, std::pair{kSensorLagSlot, n.sensor_lag}}) {
    if (setting.fixed) p[slot] = setting.value;
  }
  return p;
}

ThermalCriterion thermal_criterion(std::span<const WindowSample> window, const ParamVector& start,
                                   const FitSettings& settings) {
  FitState state;
  state.p = start;
  if (!state.p.allFinite()) return {};
  FitContext ctx(window, settings);
  if (fit_thermal(ctx, state) != StopReason::none) return {};
  const double variance = state.noise.tbar;
  if (!std::isfinite(variance) || !(variance > 0.0)) return {};
  int k = 0;
  for (const bool f : thermal_slots(settings)) k += f ? 1 : 0;
  const double n = static_cast<double>(window.size());
  return {n * std::log(variance) + k * std::log(n), state.p[kSensorLagSlot], state.p};
}

// χ²₁'s quantile at 0.99: IntervalEvidence::threshold.
constexpr double kIntervalThreshold = 6.6349;

// `after` when `margin` (the criterion's advantage of `after` over `before`, net of any price) is
// positive, with |margin| as the evidence.
IntervalChoice decided_by(double margin) {
  IntervalChoice out;
  out.interval = margin > 0.0 ? VoltageInterval::after : VoltageInterval::before;
  out.evidence = {.estimated = true,
                  .determined = std::abs(margin) >= kIntervalThreshold,
                  .statistic = std::abs(margin),
                  .threshold = kIntervalThreshold};
  return out;
}

// The thermal criterion at the best of kSwitchPhases on `window` prepared under `interval` (one
// evaluation, phase 0, where the voltage does not switch).
struct PhasedCriterion {
  ThermalCriterion criterion;
  SwitchPhase switches;
};

PhasedCriterion best_switch_phase(std::span<const WindowSample> window, VoltageInterval interval,
                                  const Vector6& theta_start, const FitSettings& settings,
                                  std::vector<WindowSample>& storage) {
  PhasedCriterion best;
  for (const double phase : kSwitchPhases) {
    const std::span<const WindowSample> prepared = prepare_window(
        window, settings.voltage_hold, interval, storage, settings.voltage_shape, phase);
    const std::size_t count =
        settings.voltage_hold == estimator::VoltageHold::foh ? count_voltage_switches(prepared) : 0;
    const ThermalCriterion c =
        thermal_criterion(prepared, thermal_start(prepared, theta_start, settings), settings);
    if (phase == kSwitchPhases.front() || c.score < best.criterion.score)
      best = {c, {count, phase}};
    if (count == 0) break;
  }
  return best;
}

// The interval from the thermal fits with the lag held at 0 and free, each [before, after].
IntervalChoice pick_interval(const std::array<ThermalCriterion, 2>& held,
                             const std::array<ThermalCriterion, 2>& free, bool lag_free,
                             std::span<const WindowSample> window) {
  const IntervalChoice by_held = decided_by(held[0].score - held[1].score);
  if (!lag_free) return by_held;
  const ThermalCriterion& best_free = free[1].score < free[0].score ? free[1] : free[0];
  if (!(best_free.score < std::min(held[0].score, held[1].score))) return by_held;
  // A free lag fits better. A lag of a period or so is the other interval in disguise (the lag
  // and the shift trade to first order, and the criterion's one slot is too little a price at a
  // coarse T sensor's noise): the shift, a discrete choice, is made without it.
  if (best_free.lag <= kShiftLikeLagPeriods * mean_sample_period(window)) return by_held;
  // A real lag (tenths of a second): the interval shows only in the second-order term, so
  // `after`, the other convention than the daemon's, has to earn its place like a parameter.
  return decided_by(free[0].score - free[1].score - std::log(static_cast<double>(window.size())));
}

}  // namespace

VoltageInterval choose_voltage_interval(std::span<const WindowSample> window,
                                        const Vector6& theta_start, const FitSettings& settings) {
  return weigh_voltage_interval(window, theta_start, settings).interval;
}

IntervalChoice weigh_voltage_interval(std::span<const WindowSample> window,
                                      const Vector6& theta_start, const FitSettings& settings) {
  // A one-period shift of the voltage and a first-order lag of the sensor look alike in T̄ (to
  // O(Δ·τs·T̄'')): with the lag free, `after` with a lag of minus one period fits a record logged
  // `before` about as well, and `before` with a lag of one period one logged `after`. So each
  // interval is fitted with the lag held at 0 and free, and pick_interval weighs them.
  FitSettings held = settings;
  const bool lag_free = !settings.nuisance.sensor_lag.fixed;
  if (lag_free) held.nuisance.sensor_lag = {.fixed = true, .value = 0.0};
  std::vector<WindowSample> storage;
  std::array<ThermalCriterion, 2> held_fit, free_fit;
  std::array<SwitchPhase, 2> switches;
  const std::array<VoltageInterval, 2> intervals{VoltageInterval::before, VoltageInterval::after};
  for (std::size_t i = 0; i < intervals.size(); ++i) {
    const PhasedCriterion phased =
        best_switch_phase(window, intervals[i], theta_start, held, storage);
    held_fit[i] = phased.criterion;
    switches[i] = phased.switches;
    if (!lag_free) continue;
    const std::span<const WindowSample> prepared =
        prepare_window(window, settings.voltage_hold, intervals[i], storage, settings.voltage_shape,
                       switches[i].phase);
    free_fit[i] = thermal_criterion(
        prepared, thermal_start(prepared, theta_start, settings, &held_fit[i]), settings);
  }
  IntervalChoice choice = pick_interval(held_fit, free_fit, lag_free, window);
  const bool after = choice.interval == VoltageInterval::after;
  choice.switches = switches[after ? 1 : 0];
  choice.other_switches = switches[after ? 0 : 1];
  return choice;
}

SwitchPhase choose_switch_phase(std::span<const WindowSample> window, VoltageInterval interval,
                                const Vector6& theta_start, const FitSettings& settings) {
  if (settings.voltage_hold != estimator::VoltageHold::foh ||
      settings.voltage_shape != VoltageShape::smooth)
    return {};
  std::vector<WindowSample> storage;
  return best_switch_phase(window, interval, theta_start, settings, storage).switches;
}

}  // namespace scp::refine

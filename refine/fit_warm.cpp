// The warm refit (refine/warm_start.hpp): the last stage of the full fit (refine/fit.cpp) from the
// previous window's solution shifted to this one.
#include <algorithm>
#include <limits>
#include <vector>

#include "refine/interval_averaging.hpp"
#include "refine/lag_hold.hpp"
#include "refine/model_simulator.hpp"
#include "refine/stages.hpp"
#include "refine/voltage_timing.hpp"
#include "refine/warm_start.hpp"

namespace scp::refine {

namespace {

bool same(const NuisanceSetting& a, const NuisanceSetting& b) {
  return a.fixed == b.fixed && (!a.fixed || a.value == b.value);
}

// Everything that changes what a fit estimates or how (not the cancel flag, not the warm start).
bool same_settings(const FitSettings& a, const FitSettings& b) {
  return a.max_iterations == b.max_iterations && a.known == b.known && a.hac_lags == b.hac_lags &&
         a.covariance_batches == b.covariance_batches && a.max_evaluations == b.max_evaluations &&
         a.max_input_delay_s == b.max_input_delay_s &&
         a.sample_timing_jitter == b.sample_timing_jitter &&
         a.outlier_threshold == b.outlier_threshold &&
         a.landing_timing_jitter == b.landing_timing_jitter && a.voltage_hold == b.voltage_hold &&
         a.voltage_interval == b.voltage_interval &&
         a.check_declared_interval == b.check_declared_interval &&
         a.voltage_shape == b.voltage_shape && same(a.nuisance.x_zero, b.nuisance.x_zero) &&
         same(a.nuisance.ambient_offset, b.nuisance.ambient_offset) &&
         same(a.nuisance.ambient_drift, b.nuisance.ambient_drift) &&
         same(a.nuisance.sensor_lag, b.nuisance.sensor_lag) &&
         a.extensions.resistance_tempco == b.extensions.resistance_tempco &&
         a.extensions.stiffness_softening == b.extensions.stiffness_softening &&
         a.extensions.cooling_tempco == b.extensions.cooling_tempco &&
         a.declared_noise == b.declared_noise;
}

// The fit so far as the previous window's fit left it, at this window's first sample.
FitState shifted_state(std::span<const WindowSample> window, const WarmStart& warm,
                       const FitSettings& settings) {
  FitState state;
  state.p = param_vector(warm.theta, warm.state);
  state.p[kXZeroSlot] = warm.nuisance[0];
  state.p[kAmbientOffsetSlot] = warm.nuisance[1];
  state.p[kAmbientDriftSlot] = warm.nuisance[2];
  state.p[kSensorLagSlot] = warm.sensor_lag;
  const Tempcos tc = tempcos_of(warm.extensions);
  state.p[kResistanceTempcoSlot] = tc.rho;
  state.p[kStiffnessSofteningSlot] = tc.kappa;
  state.p[kCoolingTempcoSlot] = tc.gamma;
  state.noise.x = warm.noise_variance[0];
  state.noise.tbar = warm.noise_variance[1];
  state.noise.timing = warm.timing_variance;
  state.noise.timing_estimated = settings.sample_timing_jitter;
  state.delay.ok = warm.input_delay_estimated;
  state.delay.delay = warm.input_delay_s;
  state.delay.sigma = warm.input_delay_sigma_s;
  state.delay.sigma_inflation = warm.input_delay_sigma_inflation;
  // The thermal stage's model range is not at hand: the measured T̄'s serves the same checks (the
  // joint stage widens it by every pass's model).
  const auto [lo, hi] = std::minmax_element(
      window.begin(), window.end(),
      [](const WindowSample& a, const WindowSample& b) { return a.tbar < b.tbar; });
  state.range = {lo->tbar - warm.nuisance[1], hi->tbar - warm.nuisance[1]};
  return state;
}

// The warm refit's extensions as the full fit that chose them reported them: the modes asked
// for and, for `auto`, the criterion that decided.
void carry_choice(const Extensions& chosen, const ExtensionSettings& asked, Extensions& out) {
  for (const ExtensionSlot& e : kExtensionTable) {
    ExtensionEstimate& o = out.*e.estimate;
    const ExtensionEstimate& c = chosen.*e.estimate;
    o.mode = asked.*e.mode;
    o.criterion = c.criterion;
    o.criterion_difference = c.criterion_difference;
  }
}

// The joint stage from a converged neighbour's solution: Gauss–Newton's own step first, which
// converges in one or two where the default damping held back most of the step along the common
// scale of θ1..θ4; each pass carries the covariance's sums (with the previous fit's
// Newey–West lags), so that the pass that shows convergence is also the covariance's, and the
// first step is taken on the one-step rule (refine/levenberg_marquardt.hpp): the start's pass
// and a cost-only pass at the step, where a second full pass would confirm it. Not where
// the covariance needs more than that pass at the solution's own weights: an estimated delay's
// error (a second pass), or the samples' timing jitter (its reference trajectory is the round's
// start).
StageOptions neighbour_options(const WarmStart& from, const FitState& state,
                               const FitSettings& settings, const TrialCovariance& sums) {
  StageOptions options;
  options.initial_damping = 0.0;
  options.decrement_tolerance = kWarmDecrementTolerance;
  if (from.hac_lags > 0 && !state.delay.ok && !settings.sample_timing_jitter) {
    options.trial_covariance = &sums;
    // The step's decrement left is below the mismatch this rule bounds: the same convergence.
    options.one_step_tolerance = kWarmDecrementTolerance;
  }
  return options;
}

// The joint stage from this window's own solution, its samples changed a little: Gauss–Newton's
// step first and each trial pass with the covariance's sums (at the start's Newey–West lags, which
// estimate_covariance uses only where the solution's own residuals choose the same), at the full
// fit's tolerance. Not where the covariance needs more than one pass (neighbour_options).
StageOptions same_window_options(const WarmStart& from, const FitState& state,
                                 const FitSettings& settings, const TrialCovariance& sums) {
  StageOptions options;
  options.initial_damping = 0.0;
  if (from.hac_lags > 0 && !state.delay.ok && !settings.sample_timing_jitter)
    options.trial_covariance = &sums;
  return options;
}

FitResult declined(FitResult& result, WarmFallback why) {
  result.warm = false;
  result.warm_fallback = why;
  return result;
}

}  // namespace

WarmStart warm_start(const FitResult& fit, const FitSettings& settings, const WindowSample& first) {
  WarmStart w;
  w.settings = settings;
  w.settings.cancel = nullptr;
  w.settings.warm = nullptr;
  w.converged = fit.converged;
  w.t_begin = fit.t_begin;
  w.t_end = fit.t_end;
  w.theta = fit.theta;
  w.state = fit.initial_state;
  w.at = first;
  w.nuisance = {fit.nuisance.x_zero.value, fit.nuisance.ambient_offset.value,
                fit.nuisance.ambient_drift.value};
  w.sensor_lag = fit.nuisance.sensor_lag.value;
  w.sensor_lag_held = fit.sensor_lag_held;
  w.noise_variance = fit.noise_sigma.cwiseProduct(fit.noise_sigma);
  w.timing_variance = fit.sample_timing_sigma_s * fit.sample_timing_sigma_s;
  w.input_delay_estimated = fit.input_delay_estimated;
  w.input_delay_s = fit.input_delay_s;
  w.input_delay_sigma_s = fit.input_delay_sigma_s;
  w.input_delay_sigma_inflation = fit.input_delay_sigma_inflation;
  w.voltage_interval = fit.voltage_interval;
  w.voltage_interval_evidence = fit.voltage_interval_evidence;
  w.interval_covariance = fit.interval_covariance;
  w.voltage_switches = fit.voltage_switches;
  w.placed_switches = fit.placed_switches;
  w.extensions = fit.extensions;
  w.hac_lags = fit.hac_lags;
  return w;
}

FitSettings with_chosen_extensions(const FitSettings& settings, const Extensions& chosen) {
  FitSettings out = settings;
  for (const ExtensionSlot& e : kExtensionTable) {
    ExtensionMode& mode = out.extensions.*e.mode;
    if (mode == ExtensionMode::automatic)
      mode = (chosen.*e.estimate).kept ? ExtensionMode::on : ExtensionMode::off;
  }
  return out;
}

void shift(WarmStart& warm, const WindowSample& from, const WindowSample& next) noexcept {
  // One that cannot apply is not stepped: applicable() declines it before it reads the
  // trajectory, whose simulation, where the fit went unstable, overflows at every sample (libm's
  // overflow path: 0.1 ms a sample).
  if (!warm.converged || !warm.state.allFinite()) return;
  const WindowSample to =
      prepared_sample(from, next, warm.settings.voltage_hold, warm.voltage_interval);
  ModelState s{warm.state[0], warm.state[1], warm.state[2]};
  ThermalCache cache;
  advance_interval(warm.theta, warm.at, to, warm.input_delay_s, s, cache, nullptr,
                   tempcos_of(warm.extensions));
  warm.state = {s.x, s.xdot, s.tbar};
  warm.nuisance[1] += warm.nuisance[2] * (to.t - warm.at.t);
  warm.at = to;
}

WarmFallback applicable(const WarmStart& warm, std::span<const WindowSample> window,
                        const FitSettings& settings) {
  if (!same_settings(warm.settings, settings)) return WarmFallback::settings_changed;
  if (!warm.converged) return WarmFallback::not_converged_before;
  if (window.empty() || warm.at.t != window.front().t || !(window.front().t <= warm.t_end))
    return WarmFallback::no_overlap;
  if (!warm.state.allFinite() || !warm.theta.allFinite()) return WarmFallback::no_overlap;
  if (window.back().t - window.front().t > kWarmWindowGrowth * (warm.t_end - warm.t_begin))
    return WarmFallback::window_grown;
  return WarmFallback::none;
}

FitResult joint_refit(std::span<const WindowSample> prepared, const WarmStart& from,
                      const FitSettings& settings, int max_iterations, RefitStart start) {
  FitResult result;
  result.theta = from.theta;
  result.voltage_interval = from.voltage_interval;
  result.voltage_interval_evidence = from.voltage_interval_evidence;
  result.voltage_switches = from.voltage_switches;
  result.samples = prepared.size();
  result.t_begin = prepared.front().t;
  result.t_end = prepared.back().t;
  FitContext ctx(prepared, settings);
  ctx.max_iterations = std::min(ctx.max_iterations, max_iterations);
  FitState state = shifted_state(prepared, from, settings);
  if (state.delay.ok) ctx.budget.set_input_delay(state.delay.delay);
  TrialCovariance sums = covariance_sums(ctx, from.hac_lags);
  sums.only_at_own_lags = start == RefitStart::same_window;
  if (start == RefitStart::neighbour)
    ctx.joint_options = neighbour_options(from, state, settings, sums);
  else if (start == RefitStart::same_window)
    ctx.joint_options = same_window_options(from, state, settings, sums);
  StopReason stop =
      from.sensor_lag_held ? judge_held_lag(ctx, state, from.sensor_lag) : StopReason::none;
  if (stop == StopReason::none) stop = fit_joint(ctx, state);
  if (stop == StopReason::none && !state.joint.converged) {
    result.iterations = state.iterations;
    result.evaluations = ctx.budget.evaluations();
    result.message = state.joint.message;
    return result;
  }
  conclude(ctx, state, stop, result);
  return result;
}

namespace {

FitResult refit_window(std::span<const WindowSample> window, const WarmStart& warm,
                       const FitSettings& settings) {
  FitResult result;
  result.theta = warm.theta;
  if (const WarmFallback why = applicable(warm, window, settings); why != WarmFallback::none)
    return declined(result, why);
  std::vector<WindowSample> storage;
  const std::span<const WindowSample> prepared =
      prepare_window(window, settings.voltage_hold, warm.voltage_interval, storage,
                     settings.voltage_shape, warm.voltage_switches.phase);
  const bool placed = !warm.placed_switches.empty() && prepared.data() == storage.data() &&
                      restore_placed_switches(storage, warm.placed_switches) > 0;
  const FitSettings chosen = with_chosen_extensions(settings, warm.extensions);
  result = joint_refit(prepared, warm, chosen, kWarmIterations, RefitStart::neighbour);
  if (placed && result.validated)
    result = fit_with_placed_switches(storage, chosen, std::move(result), PlacementStep::follows);
  if (settings.voltage_hold == estimator::VoltageHold::foh)
    result.voltage_switches.count = count_voltage_switches(prepared);
  if (!result.validated && !result.converged) return declined(result, WarmFallback::not_converged);
  if (!result.converged) return declined(result, WarmFallback::verdict_failed);
  if (result.validation.structure_found()) return declined(result, WarmFallback::structure_found);
  carry_choice(warm.extensions, settings.extensions, result.extensions);
  // The choice's doubt, measured when the full fit compared the two intervals.
  add_interval_covariance(result, warm.interval_covariance);
  result.warm = true;
  result.warm_fallback = WarmFallback::none;
  return result;
}

}  // namespace

FitResult refit(std::span<const WindowSample> window, const WarmStart& warm,
                const FitSettings& settings) {
  FitResult result = refit_window(window, warm, settings);
  result.validator.reset();  // its block means served the fit's own tests
  return result;
}

FitResult refit_same_window(std::span<const WindowSample> prepared, const FitResult& fitted,
                            const FitSettings& settings) {
  const WarmStart from = warm_start(fitted, settings, prepared.front());
  FitResult result =
      joint_refit(prepared, from, with_chosen_extensions(settings, fitted.extensions),
                  std::numeric_limits<int>::max(), RefitStart::same_window);
  carry_choice(fitted.extensions, settings.extensions, result.extensions);
  return result;
}

}  // namespace scp::refine

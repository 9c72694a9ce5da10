// The staged output-error fit of refine/fit.hpp. Each stage is a Levenberg–Marquardt run on
// streamed normal equations (refine/stage.hpp) or a 1-D search, over the slots of p it can
// determine at that point (refine/stages.hpp):
//   (a)  thermal: θ5, θ6, T̄0 on T̄ alone (the thermal block does not see x);
//   (a') with FitSettings::max_input_delay_s, the voltage's delay from T̄ (refine/input_delay.hpp);
//   (b)  the common scale of θ1..θ4, when all four are free (refine/scale_search.hpp);
//   (c)  mechanical: θ1..θ4, x0, ẋ0 on x, with T̄ simulated from the thermal fit;
//   (d)  joint: every free slot on x and T̄, the noise model re-estimated until it settles;
// then the covariance at the solution and the verdict on it. Every pass counts against one
// Budget; a stage that ends the fit says why (refine/stop_reason.hpp), and the result then
// carries θ where the fit got to.

#include "refine/fit.hpp"

#include <algorithm>
#include <cmath>
#include <optional>
#include <vector>

#include "refine/fitted_sweep.hpp"
#include "refine/heater_power.hpp"
#include "refine/information_criteria.hpp"
#include "refine/interval_averaging.hpp"
#include "refine/stages.hpp"
#include "refine/switch_columns.hpp"
#include "refine/switch_placement.hpp"
#include "refine/voltage_timing.hpp"
#include "refine/warm_start.hpp"

namespace scp::refine {

namespace {

// ρ(A) of the mechanical block at the extremes of T̄ (the bound substeps() uses).
double stiffness(const ParamVector& p, const TbarRange& range) {
  const double damping = std::max(std::abs(p[kDamping] + p[kDampingSlope] * range.lo),
                                  std::abs(p[kDamping] + p[kDampingSlope] * range.hi));
  return damping + std::sqrt(std::abs(p[kStiffness]));
}

FitResult ended(FitResult& result, StopReason reason) {
  result.stop = reason;
  result.message = to_text(reason);
  return result;
}

// θ and the initial state where the fit got to, and what the stages so far estimated.
void take_progress(const FitContext& ctx, const FitState& state, FitResult& result) {
  result.iterations = state.iterations;
  result.evaluations = ctx.budget.evaluations();
  result.theta = theta_of(state.p);
  result.initial_state = initial_state_of(state.p);
  if (state.delay.ok) {
    result.input_delay_estimated = true;
    result.input_delay_s = state.delay.delay;
    result.input_delay_sigma_s = state.delay.sigma;
    result.input_delay_sigma_inflation = state.delay.sigma_inflation;
  }
  result.sample_timing_sigma_s = state.sample_timing_sigma_s;
  const NuisanceSettings& n = ctx.settings.nuisance;
  result.nuisance.x_zero = {!n.x_zero.fixed, state.p[kXZeroSlot], 0.0};
  result.nuisance.ambient_offset = {!n.ambient_offset.fixed, state.p[kAmbientOffsetSlot], 0.0};
  result.nuisance.ambient_drift = {!n.ambient_drift.fixed, state.p[kAmbientDriftSlot], 0.0};
  result.nuisance.sensor_lag = {!n.sensor_lag.fixed, state.p[kSensorLagSlot], 0.0};
  result.sensor_lag_held = state.sensor_lag_held;
  for (const ExtensionSlot& e : kExtensionTable) {
    ExtensionEstimate& out = result.extensions.*e.estimate;
    out.mode = ctx.settings.extensions.*e.mode;
    out.kept = out.mode != ExtensionMode::off;
    out.value = state.p[e.slot];
  }
}

}  // namespace

// The steady T̄ the window's largest V² would hold at θ: a temperature its voltage can drive the
// actuator to, where the model must hold too (a short window that never gets there could
// otherwise claim a damping that changes sign just beyond it).
double steady_tbar(std::span<const WindowSample> window, const ParamVector& p) {
  double u = 0.0;
  for (const WindowSample& s : window) u = std::max(u, s.voltage * s.voltage);
  const double t = p[kHeating] * u / p[kCooling];
  return std::isfinite(t) ? t : 0.0;
}

StopReason verdict(const FitContext& ctx, const FitState& state,
                   const CovarianceOutcome& covariance) {
  const TbarRange seen{
      std::min(covariance.model_range.lo, state.range.lo),
      std::max({covariance.model_range.hi, state.range.hi, steady_tbar(ctx.window, state.p)})};
  if (!stable_over(state.p, seen)) return StopReason::model_unstable;
  if (!(stiffness(state.p, seen) * ctx.budget.mean_interval() <= kUnresolvedPolePerSample))
    return StopReason::fast_pole_unresolved;
  if (!covariance.definite) return StopReason::covariance_singular;
  if (state.delay.at_limit) return StopReason::input_delay_at_limit;
  return StopReason::none;
}

namespace {

// conclude()'s end, once every stage ran.
void conclude_with_covariance(FitContext& ctx, const FitState& state, FitResult& result) {
  const CovarianceOutcome covariance = estimate_covariance(ctx, state, result);
  if (covariance.stop != StopReason::none) {
    take_progress(ctx, state, result);
    ended(result, covariance.stop);
    return;
  }
  result.stop = verdict(ctx, state, covariance);
  result.converged = state.joint.converged && result.stop == StopReason::none;
  result.message = result.stop == StopReason::none ? state.joint.message : to_text(result.stop);
}

// conclude() but for the covariance's pass, which waits in `pending`: the verdict on the T̄ the
// solution's pass saw, whose definiteness the covariance will judge.
void conclude_but_covariance(FitContext& ctx, const FitState& state, FitResult& result,
                             std::optional<PendingCovariance>& pending) {
  take_progress(ctx, state, result);
  publish_solution_pass(ctx, state, result);
  CovarianceOutcome seen;
  seen.definite = true;
  seen.model_range = {state.joint.pass.tbar_min, state.joint.pass.tbar_max};
  result.stop = verdict(ctx, state, seen);
  result.converged = state.joint.converged && result.stop == StopReason::none;
  result.message = result.stop == StopReason::none ? state.joint.message : to_text(result.stop);
  pending = PendingCovariance{ctx, state};
}

}  // namespace

void conclude(FitContext& ctx, const FitState& state, StopReason stop, FitResult& result) {
  take_progress(ctx, state, result);
  if (stop != StopReason::none) {
    ended(result, stop);
    return;
  }
  conclude_with_covariance(ctx, state, result);
}

void conclude_deferred(PendingCovariance& pending, FitResult& result) {
  const int iterations = result.iterations;  // with the retried shapes' (fit_staged)
  conclude_with_covariance(pending.ctx, pending.state, result);
  result.iterations = iterations;
}

namespace {

// Shapes of the mechanical block tried, in this order, when the fit from the default shape
// fails: θ3/θ1 (the default's is 1, an overdamped pair) grows by 30 at each, toward lightly
// damped pairs. The scale search moves the damping ratio and the natural frequency together
// (both as the square root of the common scale, θ1/θ3 fixed), so it cannot reach another ratio
// by itself, and a lightly damped actuator whose dynamics the excitation barely reaches is
// explained almost as well by the slow overdamped pair the default shape leads to.
constexpr std::array<MechanicalShape, 3> kRetryShapes = {
    {{1.0, 30.0}, {1.0, 1000.0}, {1.0, 30000.0}}};

bool out_of_budget(StopReason stop) {
  return stop == StopReason::cancelled || stop == StopReason::evaluation_budget_spent ||
         stop == StopReason::work_budget_spent;
}

FitResult fresh_result(std::span<const WindowSample> window, const Vector6& theta_start) {
  FitResult result;
  result.theta = theta_start;
  result.samples = window.size();
  result.t_begin = window.front().t;
  result.t_end = window.back().t;
  return result;
}

// The stages after the thermal ones, and the verdict; with `pending`, the covariance waits there
// where every stage ran.
void fit_mechanics(FitContext& ctx, FitState& state, bool default_shape, FitResult& result,
                   std::optional<PendingCovariance>* pending) {
  if (default_shape) start_displacement_zero(ctx.window, ctx.settings, state.p);
  start_with_positive_damping(ctx, state);
  StopReason stop = StopReason::none;
  if (ctx.settings.search_scale) stop = search_scale(ctx, state);
  if (stop == StopReason::none) stop = fit_mechanical(ctx, state);
  if (stop == StopReason::none) stop = fit_joint(ctx, state);
  if (pending != nullptr) pending->reset();
  if (pending != nullptr && stop == StopReason::none) {
    conclude_but_covariance(ctx, state, result, *pending);
  } else {
    conclude(ctx, state, stop, result);
  }
}

FitResult fit_staged_with(std::span<const WindowSample> window, const Vector6& theta_start,
                          const FitSettings& settings, std::optional<PendingCovariance>* pending) {
  if (pending != nullptr) pending->reset();
  FitResult result = fresh_result(window, theta_start);
  FitState state;
  state.p = start_point(window, theta_start, settings.known);
  set_nuisance_start(settings.nuisance, state.p);
  if (!state.p.allFinite()) return ended(result, StopReason::start_not_finite);

  FitContext ctx(window, settings);
  StopReason stop = fit_thermal(ctx, state);
  if (stop == StopReason::none) stop = hold_undetermined_lag(ctx, state);
  if (stop == StopReason::none) stop = fit_input_delay(ctx, state);
  if (stop != StopReason::none) {
    conclude(ctx, state, stop, result);
    return result;
  }
  const bool default_shape = !usable_mechanical_start(theta_start);
  const FitState thermal_state = state;
  FitContext attempt_ctx = ctx;
  fit_mechanics(attempt_ctx, state, default_shape, result, pending);
  for (const MechanicalShape& shape : kRetryShapes) {
    if (!default_shape || result.converged || out_of_budget(result.stop)) break;
    FitContext retry_ctx = ctx;
    retry_ctx.budget = attempt_ctx.budget;  // every attempt's passes count against one budget
    retry_ctx.budget.restart_path();
    FitState retry = thermal_state;
    start_mechanical_shape(window, shape, settings.known, retry.p);
    FitResult attempt = fresh_result(window, theta_start);
    fit_mechanics(retry_ctx, retry, true, attempt, pending);
    attempt.iterations += result.iterations - thermal_state.iterations;
    result = attempt;
    attempt_ctx = retry_ctx;
  }
  return result;
}

}  // namespace

FitResult fit_staged(std::span<const WindowSample> window, const Vector6& theta_start,
                     const FitSettings& settings) {
  return fit_staged_with(window, theta_start, settings, nullptr);
}

FitResult fit_staged_deferring_covariance(std::span<const WindowSample> prepared,
                                          const Vector6& theta_start, const FitSettings& settings,
                                          std::optional<PendingCovariance>& pending) {
  return fit_staged_with(prepared, theta_start, settings, &pending);
}

namespace {

bool has_automatic(const ExtensionSettings& e) {
  return e.resistance_tempco == ExtensionMode::automatic ||
         e.stiffness_softening == ExtensionMode::automatic ||
         e.cooling_tempco == ExtensionMode::automatic;
}

// fit() on a window whose voltage timing is WindowSample's (refine/voltage_timing.hpp).
FitResult fit_prepared(std::span<const WindowSample> window, const Vector6& theta_start,
                       const FitSettings& settings) {
  return has_automatic(settings.extensions) ? select_extensions(window, theta_start, settings)
                                            : fit_staged(window, theta_start, settings);
}

// Rounds of placing the switches and fitting θ again (refine/switch_placement.hpp): the first only
// where the data ask for a phase per switch (Schwarz's criterion), the others until a step would
// take less than kSettledDecrease off the weighted cost (χ²: within the noise), which is not taken:
// θ stays fitted at the phases it was fitted at, and that step's sweep gives the phases' share of
// the covariance. The step profiles θ out, but its model is linear in the phases (and θ's
// nonlinear), so θ's refit and another step take what one step left.
constexpr int kPlacementRounds = 6;
constexpr double kSettledDecrease = 1.0;

// The passes and iterations of the fits a result replaced, which its own counts leave out.
struct FitCost {
  int iterations = 0, evaluations = 0;
  void add(const FitResult& r) {
    iterations += r.iterations;
    evaluations += r.evaluations;
  }
};

// Whether two fits kept the same extensions.
bool same_extensions(const Extensions& a, const Extensions& b) {
  for (const ExtensionSlot& e : kExtensionTable)
    if ((a.*e.estimate).kept != (b.*e.estimate).kept) return false;
  return true;
}

// A fit at placed phases and, where the rounds ended on a settled step, what the phases add to
// its covariance (placed_switches_covariance's, from that step's sweep).
struct PlacedFit {
  FitResult fit;
  std::optional<Matrix6> covariance_share;
};

// The rounds of placement from `fitted`, each followed by θ's refit of the same model; what the
// replaced or discarded fits cost is added to `cost`. `pending`: where `fitted`'s covariance waits,
// concluded where no refit replaced it.
PlacedFit placement_rounds(std::span<WindowSample> prepared, const FitSettings& settings,
                           const FitSettings& refit, FitResult fitted, PlacementStep first,
                           FitCost& cost, PendingCovariance* pending) {
  PlacedFit out;
  bool replaced = false;
  for (int round = 0; round < kPlacementRounds && fitted.validated; ++round) {
    const SwitchPlacement placed =
        place_voltage_switches(prepared, fitted, settings.known,
                               round == 0 ? first : PlacementStep::follows, kSettledDecrease);
    if (placed.placed == 0) break;
    fitted.voltage_switches.placed = placed.placed;
    fitted.voltage_switches.rms_phase_sigma = placed.rms_phase_sigma;
    if (placed.settled) {
      out.covariance_share = placed.covariance_share;
      break;
    }
    FitResult next = refit_same_window(prepared, fitted, refit);
    if (!next.validated) {  // the fit of the last phases that ran to its verdict stands
      cost.add(next);
      break;
    }
    cost.add(fitted);
    next.voltage_switches = fitted.voltage_switches;
    fitted = std::move(next);
    replaced = true;
  }
  if (!replaced && pending != nullptr) conclude_deferred(*pending, fitted);
  out.fit = std::move(fitted);
  return out;
}

}  // namespace

FitResult fit_with_placed_switches(std::span<WindowSample> prepared, const FitSettings& settings,
                                   FitResult fitted, PlacementStep first,
                                   PendingCovariance* pending) {
  FitSettings refit = settings;
  refit.search_scale = false;  // θ1..θ4's common scale is the fitted one's
  FitCost cost;
  PlacedFit placed =
      placement_rounds(prepared, settings, refit, std::move(fitted), first, cost, pending);
  fitted = std::move(placed.fit);
  // The rounds kept the model of the fit at one phase (with `auto`, fit_placing_switches's
  // extended one); `auto` chooses at the placed phases, where a switch's misplaced heat no
  // longer passes for a missing term, each model weighed at phases of its own. Where the choice
  // changed the model, the phases are placed again for the model chosen.
  if (has_automatic(settings.extensions) && fitted.voltage_switches.placed > 0) {
    FitResult next = reselect_extensions(prepared, fitted, refit);
    if (next.validated && next.converged) {
      const bool changed = !same_extensions(next.extensions, fitted.extensions);
      cost.add(fitted);
      next.voltage_switches = fitted.voltage_switches;
      placed = {std::move(next), std::nullopt};
      if (changed)
        placed = placement_rounds(prepared, settings, refit, std::move(placed.fit),
                                  PlacementStep::follows, cost, nullptr);
      fitted = std::move(placed.fit);
    } else {
      cost.add(next);
    }
  }
  fitted.iterations += cost.iterations;
  fitted.evaluations += cost.evaluations;
  // σ counts the phases as the unknowns they are.
  if (fitted.voltage_switches.placed > 0 && fitted.validated)
    add_covariance_share(fitted, placed.covariance_share ? *placed.covariance_share
                                                         : placed_switches_covariance(
                                                               prepared, fitted, settings.known));
  if (fitted.voltage_switches.placed > 0) {
    fitted.placed_switches = placed_switches(prepared);
    // The final pass's validation left the phases out of what the fit explains.
    if (fitted.validated && fitted.validator != nullptr)
      fitted.validation = fitted.validator->finish(
          placed_switch_columns(prepared, fitted, fitted.validator->thermal_layout()));
  }
  return fitted;
}

bool places_switches(const FitSettings& settings, const SwitchPhase& switches) {
  return switches.count > 0 && settings.voltage_hold == estimator::VoltageHold::foh &&
         settings.voltage_shape == VoltageShape::smooth;
}

namespace {

// The fit of a window whose switches may be placed: placed from the fit at one phase where the
// data ask for it. With an `auto` extension the choice waits for the phases: they are placed for
// the extended model, which holds every model the choice can make, and the choice is then made
// at them (fit_with_placed_switches); made at one phase where nothing was placed.
FitResult fit_placing_switches(std::span<WindowSample> prepared, const Vector6& theta_start,
                               const FitSettings& settings, const SwitchPhase& switches) {
  const bool automatic = has_automatic(settings.extensions);
  // The fit at one phase is replaced where the switches are placed: its covariance waits.
  std::optional<PendingCovariance> pending;
  FitResult result =
      automatic ? fit_extended(prepared, theta_start, settings)
                : fit_staged_deferring_covariance(prepared, theta_start, settings, pending);
  result.voltage_switches = switches;
  result = fit_with_placed_switches(prepared, settings, std::move(result),
                                    PlacementStep::needs_evidence, pending ? &*pending : nullptr);
  if (automatic && result.voltage_switches.placed == 0 && is_extended(result, settings)) {
    result = eliminate_extensions(prepared, std::move(result), settings, ExtensionWeighing::bic);
    result.voltage_switches = switches;
  }
  return result;
}

// The staged fit of the window read under `interval`, its switches at `switches` and then, where
// it has any, each where the residuals place it.
FitResult fit_under(std::span<const WindowSample> window, const Vector6& theta_start,
                    const FitSettings& settings, VoltageInterval interval,
                    const SwitchPhase& switches) {
  std::vector<WindowSample> storage;
  const std::span<const WindowSample> prepared = prepare_window(
      window, settings.voltage_hold, interval, storage, settings.voltage_shape, switches.phase);
  FitResult result;
  if (places_switches(settings, switches) && prepared.data() == storage.data()) {
    result = fit_placing_switches(storage, theta_start, settings, switches);
  } else {
    result = fit_prepared(prepared, theta_start, settings);
    result.voltage_switches = switches;
  }
  result.voltage_interval = interval;
  return result;
}

VoltageInterval other_interval(VoltageInterval interval) {
  return interval == VoltageInterval::after ? VoltageInterval::before : VoltageInterval::after;
}

// Schwarz's criterion of a fit over both channels: their residuals, the slots it estimated and
// the switches it placed (ln n each, as the placement's first step prices them). NaN where a
// channel has no residual to weigh (noise-free data).
double joint_criterion(const FitResult& r, const std::array<bool, 6>& known) {
  const double n = static_cast<double>(r.samples);
  const ChannelResiduals channels[2] = {{r.residual_rms[0] * r.residual_rms[0] * n, r.samples},
                                        {r.residual_rms[1] * r.residual_rms[1] * n, r.samples}};
  int parameters = static_cast<int>(r.voltage_switches.placed);
  for (const bool f : fitted_slots(r, known)) parameters += f ? 1 : 0;
  return bic(channels, parameters);
}

// What holding the sensor's lag at 0 would change in a fit's joint criterion, to second order:
// (τ̂/σ_τ)² more deviance (the cost's profile along the lag is a parabola over a few σ) and one
// slot's price less (ln of both channels' samples). 0 where the lag was held.
double lag_hold_price(const FitResult& r) {
  const NuisanceEstimate& lag = r.nuisance.sensor_lag;
  if (!lag.estimated || !(lag.sigma > 0.0)) return 0.0;
  const double z = lag.value / lag.sigma;
  return std::isfinite(z) ? z * z - std::log(2.0 * static_cast<double>(r.samples)) : 0.0;
}

// A fitted lag that a one-period shift of the voltage could stand for (kShiftLikeLagPeriods).
bool shift_like_lag(const FitResult& r, double period) {
  const NuisanceEstimate& lag = r.nuisance.sensor_lag;
  return !lag.estimated || std::abs(lag.value) <= kShiftLikeLagPeriods * period;
}

// The joint criterion of `other` minus that of `fitted` (> 0: the fitted one is the better). Both
// fits free the sensor's lag, and a lag of a period mimics the other interval: where both fitted
// lags are that short, the lag is a one-period shift in disguise, and the two are weighed with it
// held at 0, as the thermal stage's rule weighs them (refine/voltage_timing.cpp): each criterion
// plus its lag_hold_price. That lets x, through the mechanical block, tell the shift from the
// lag, which with the lag free it cannot (docs/numerics.md: the one-period shift's Δχ² with x and
// T̄, with T̄ alone and with the lag free). `lag_held` says which weighing was made.
double joint_difference(const FitResult& fitted, const FitResult& other,
                        const std::array<bool, 6>& known, double period, bool& lag_held) {
  const double free = joint_criterion(other, known) - joint_criterion(fitted, known);
  lag_held = shift_like_lag(fitted, period) && shift_like_lag(other, period) &&
             (fitted.nuisance.sensor_lag.estimated || other.nuisance.sensor_lag.estimated);
  return lag_held ? free + lag_hold_price(other) - lag_hold_price(fitted) : free;
}

// Whether the joint fits under both intervals are the evidence that stands: `difference` is the
// other's criterion minus the fitted one's (> 0: the fitted one is the better); `e` then carries
// it, determined where it reaches the threshold. Weighed with the lag held (joint_difference),
// they are better evidence than T̄ alone at any margin, since x adds to what T̄ tells: they stand
// and the better one is fitted even where the interval stays undetermined. With the lag free
// they stand only where they decide: a lag that mimics the other interval makes their
// difference small and its sign a guess (on heavy-slow at N3, whose slow mechanics see no
// millisecond, taking the free-lag fits' better one at differences of 0.1–0.7 fitted the wrong
// interval in 2 of 10 continuous files, θ1..θ4 at 4.4× their bound from 1.1×, and 3 of 10 held
// ones).
bool weighed_jointly(IntervalEvidence& e, double difference, bool lag_held) {
  if (!std::isfinite(difference)) return false;
  const bool decides = std::abs(difference) >= e.threshold;
  if (!decides && !lag_held) return false;
  e.joint = true;
  e.joint_lag_held = lag_held;
  e.thermal_statistic = e.statistic;
  e.statistic = std::abs(difference);
  e.determined = decides;
  return true;
}

// An interval T̄ alone could not tell: the fit under the other one too, the two weighed over x and
// T̄ together (where that decides it, the better one is kept). θ1..θ4 either move with it (the
// interval stays undetermined) or not (equivalent); where it stays undetermined every σ takes the
// spread.
void compare_intervals(std::span<const WindowSample> window, const Vector6& theta_start,
                       const FitSettings& settings, const IntervalChoice& choice,
                       FitResult& result) {
  FitResult alt = fit_under(window, theta_start, settings, other_interval(choice.interval),
                            choice.other_switches);
  result.iterations += alt.iterations;
  result.evaluations += alt.evaluations;
  if (!alt.converged) return;
  IntervalEvidence e = result.voltage_interval_evidence;
  bool lag_held = false;
  const double difference =
      joint_difference(result, alt, settings.known, mean_sample_period(window), lag_held);
  if (weighed_jointly(e, difference, lag_held) && difference < 0.0) {
    // the other interval fits x and T̄ together better
    alt.iterations = result.iterations;
    alt.evaluations = result.evaluations;
    std::swap(result, alt);
  }
  e.compared = true;
  e.theta_shift_sigma = mechanical_shift_sigma(result, alt, settings.known);
  e.equivalent = e.theta_shift_sigma <= kEquivalentThetaShift;
  result.voltage_interval_evidence = e;
  if (!e.determined)
    add_interval_covariance(result, interval_covariance(result, alt, e.statistic, settings.known));
}

// A declared interval T̄ alone could not check: the fit under the other one weighed against it
// over x and T̄ together. The fit keeps the declaration; the evidence says whether the data
// decide, and for which.
void check_declared_jointly(std::span<const WindowSample> window, const Vector6& theta_start,
                            const FitSettings& settings, const IntervalChoice& choice,
                            FitResult& result) {
  const FitResult alt = fit_under(window, theta_start, settings, other_interval(choice.interval),
                                  choice.other_switches);
  result.iterations += alt.iterations;
  result.evaluations += alt.evaluations;
  if (!alt.converged) return;
  bool lag_held = false;
  const double difference =
      joint_difference(result, alt, settings.known, mean_sample_period(window), lag_held);
  IntervalEvidence& e = result.voltage_interval_evidence;
  if (weighed_jointly(e, difference, lag_held)) e.contradicted = e.determined && difference < 0.0;
}

// The declared interval, with the evidence of weighing it against the other as `estimate` would
// (FitSettings::check_declared_interval).
IntervalChoice weigh_declared_interval(std::span<const WindowSample> window,
                                       const Vector6& theta_start, const FitSettings& settings) {
  const IntervalChoice data = weigh_voltage_interval(window, theta_start, settings);
  const bool agrees = data.interval == settings.voltage_interval;
  IntervalChoice declared;
  declared.interval = settings.voltage_interval;
  declared.switches = agrees ? data.switches : data.other_switches;
  declared.other_switches = agrees ? data.other_switches : data.switches;
  declared.evidence = {.determined = data.evidence.determined,
                       .statistic = data.evidence.statistic,
                       .threshold = data.evidence.threshold,
                       .checked = true,
                       .contradicted = !agrees && data.evidence.determined};
  return declared;
}

// T̄ alone decides the interval by a margin this many thresholds wide or wider without the joint
// fits. Short of it x could still overturn T̄ (the joint fits weigh both, the better evidence),
// and T̄ alone errs where a one-period shift is only a few of its σ (heavy-slow at N3;
// docs/numerics.md). Past it the other interval would need x to say three thresholds' worth
// against T̄, and a window that clear costs one fit, not two.
constexpr double kJointCheckMargins = 4.0;

// Whether the interval T̄ chose is weighed again by the joint fits under both (compare_intervals).
bool worth_weighing_jointly(const IntervalEvidence& e) {
  return !e.determined || e.statistic < kJointCheckMargins * e.threshold;
}

// The full staged fit (without FitSettings::warm).
FitResult fit_cold(std::span<const WindowSample> window, const Vector6& theta_start,
                   const FitSettings& settings) {
  IntervalChoice choice;
  if (settings.voltage_interval == VoltageInterval::estimate) {
    choice = weigh_voltage_interval(window, theta_start, settings);
  } else if (settings.check_declared_interval) {
    choice = weigh_declared_interval(window, theta_start, settings);
  } else {
    choice.interval = settings.voltage_interval;
    choice.switches = choose_switch_phase(window, choice.interval, theta_start, settings);
  }
  FitResult result = fit_under(window, theta_start, settings, choice.interval, choice.switches);
  result.voltage_interval_evidence = choice.evidence;
  if (!result.converged) return result;
  if (choice.evidence.estimated && worth_weighing_jointly(choice.evidence))
    compare_intervals(window, theta_start, settings, choice, result);
  if (choice.evidence.checked && !choice.evidence.determined)
    check_declared_jointly(window, theta_start, settings, choice, result);
  return result;
}

// fit() on a checked window.
FitResult fit_checked(std::span<const WindowSample> window, const Vector6& theta_start,
                      const FitSettings& settings) {
  if (settings.warm == nullptr) return fit_cold(window, theta_start, settings);
  FitResult warm = refit(window, *settings.warm, settings);
  if (warm.warm) return warm;
  // A seed that is the θ of a converged fit of an overlapping window (as the daemon hands it over
  // with a warm start) has the common scale of θ1..θ4 already, when only its joint stage fell
  // short of converging within the warm refit's iterations.
  FitSettings full = settings;
  if (warm.warm_fallback == WarmFallback::not_converged && settings.warm->converged &&
      theta_start == settings.warm->theta)
    full.search_scale = false;
  // The warm attempt's work counts in what the fit cost.
  FitResult result = fit_cold(window, theta_start, full);
  result.warm_fallback = warm.warm_fallback;
  result.iterations += warm.iterations;
  result.evaluations += warm.evaluations;
  return result;
}

// The final pass's validator (its block means, a few MB) serves the fit's own tests only.
FitResult without_validator(FitResult result) {
  result.validator.reset();
  return result;
}

}  // namespace

FitResult fit(std::span<const WindowSample> window, const Vector6& theta_start,
              const FitSettings& settings) {
  if (const StopReason bad = check_window(window); bad != StopReason::none) {
    FitResult result;
    result.theta = theta_start;
    return ended(result, bad);
  }
  if (!measures_current(window))
    return without_validator(fit_checked(window, theta_start, settings));
  // The measured power carries R(T̄): the resistance's extension has nothing left to model.
  FitSettings power = settings;
  power.extensions.resistance_tempco = ExtensionMode::off;
  WarmStart warm;  // the previous fit's settings as this one's, so that the warm start applies
  if (settings.warm != nullptr) {
    warm = *settings.warm;
    warm.settings.extensions.resistance_tempco = ExtensionMode::off;
    power.warm = &warm;
  }
  FitResult result = fit_checked(window, theta_start, power);
  publish_measured_power(window, result);
  return without_validator(std::move(result));
}

}  // namespace scp::refine
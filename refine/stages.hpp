#pragma once
// The stages of the fit (refine/fit.cpp), each a function of the context and the fit so far
// (refine/fit_state.hpp) that can run and be tested on its own. A stage returns
// StopReason::none to hand on, or why the fit ends here. The delay's and the scale's searches
// have files of their own (refine/input_delay.hpp, refine/scale_search.hpp).

#include <array>
#include <optional>
#include <span>

#include "refine/fit_state.hpp"
#include "refine/input_delay.hpp"
#include "refine/scale_search.hpp"
#include "refine/switch_placement.hpp"

namespace scp::refine {

// Rounds of placing the switches of `prepared` (foh, smooth; refine/switch_placement.hpp) and
// fitting θ again from `fitted`, the fit of `prepared` as it is, until a step would take less
// than 1 off the weighted cost; `first`: whether the first step needs evidence (Schwarz's
// criterion) or follows phases placed before. θ's covariance gains the phases' share, and the
// result the placed switches (FitResult::placed_switches).
struct PendingCovariance;

// `pending`: where `fitted`'s covariance waits (fit_staged_deferring_covariance), concluded if
// `fitted` stands.
FitResult fit_with_placed_switches(std::span<WindowSample> prepared, const FitSettings& settings,
                                   FitResult fitted, PlacementStep first,
                                   PendingCovariance* pending = nullptr);

// Whether the fit places the switches of a window read with `settings` that has `switches`.
bool places_switches(const FitSettings& settings, const SwitchPhase& switches);

// A window the fit can use (at least 3 samples, finite, t strictly increasing), or why not.
StopReason check_window(std::span<const WindowSample> window);

// The start: θ from `theta_start` where usable, the initial state from the first sample (at
// rest). A thermal start that is not finite and positive comes from the data (a regression of
// dT̄/dt on T̄ and V²); a mechanical one from a default shape whose static gain fits the data,
// for the scale search to place.
ParamVector start_point(std::span<const WindowSample> window, const Vector6& theta_start,
                        const std::array<bool, kThetaSize>& known);

// Whether θ_start's mechanical part can start the fit (finite, θ1 and θ3 positive); otherwise
// start_point takes a default shape whose static gain is the window's static line's.
bool usable_mechanical_start(const Vector6& theta);

// A shape of the mechanical block: θ1 and θ3 at scale 1, which the scale search multiplies
// together.
struct MechanicalShape {
  double damping, stiffness;
};
// Poles at −1 and −1000 rad/s at scale 1: an overdamped pair.
inline constexpr MechanicalShape kDefaultShape{1001.0, 1000.0};

// θ1..θ4 of p (unless known) from `shape`, with the window's static gain.
void start_mechanical_shape(std::span<const WindowSample> window, const MechanicalShape& shape,
                            const std::array<bool, kThetaSize>& known, ParamVector& p);

// With the displacement sensor's zero estimated and the default shape started (after the
// thermal stage): the zero as the constant of that static line x ≈ zero − g·T̄ (T̄ as the thermal
// stage's ambient terms leave it), and x0 the first sample less it, so that the shape's gain and
// zero come from the same line. Otherwise a zero of a fifth of the stroke starts as a
// displacement from rest whose relaxation the scale search chased to a fast pole. From a usable
// θ_start the zero starts at 0, x0 at the first sample: the search, started there with the line's
// zero, lost a paper N3 seed (16) that it finds from 0.
void start_displacement_zero(std::span<const WindowSample> window, const FitSettings& settings,
                             ParamVector& p);

// The thermal block's slots (θ5, θ6 unless known, T̄0) and its passes (T̄ alone: the thermal block
// does not see x).
FreeMask thermal_slots(const std::array<bool, kThetaSize>& known);
// The same with the T̄ nuisance terms (ambient offset and drift) unless FitSettings fixes them.
FreeMask thermal_slots(const FitSettings& settings);
PassSettings thermal_pass_settings();
// The same for a fit with FitSettings's extensions (their sensitivities, where any is estimated).
PassSettings thermal_pass_settings(const FitSettings& settings);

// The optional slots a fit under `settings` estimates (an extension, the sensor's lag): its
// Jacobian passes then carry their sensitivities (PassSettings::extensions, sensor_lag).
inline void carry_optional_slots(const FitSettings& settings, PassSettings& ps) {
  ps.extensions = settings.extensions.any();
  ps.sensor_lag = !settings.nuisance.sensor_lag.fixed;
}

// Every slot the joint stage and the covariance estimate: θ unless known, the initial state, the
// nuisance terms unless fixed, the extensions not `off`.
FreeMask fit_slots(const FitSettings& settings);

// The mechanical block's slots: θ1..θ4 unless known, x0, ẋ0.
FreeMask mechanical_slots(const std::array<bool, kThetaSize>& known);
// The same with the displacement sensor's zero unless FitSettings fixes it.
FreeMask mechanical_slots(const FitSettings& settings);

// (a) θ5, θ6, T̄0 on T̄ alone; sets the noise variance of T̄ and the model's T̄ range.
StopReason fit_thermal(FitContext& ctx, FitState& state);

// (a'') FitSettings estimates the sensor's lag, but a short window cannot tell it from the thermal
// block's other terms (refine/lag_hold.cpp: judge_sensor_lag): the lag is held at its prior value
// (0, or the warm start's) and the thermal stage run again without it. The fit then reports it
// held (FitResult::sensor_lag_held).
StopReason hold_undetermined_lag(FitContext& ctx, FitState& state);

// (c) θ1..θ4, x0, ẋ0 on x, with T̄ simulated from the thermal fit; sets x's noise variance.
StopReason fit_mechanical(FitContext& ctx, FitState& state);

// The passes of the joint stage and of the covariance at its solution: weights 1/σ̂², and with
// FitSettings::sample_timing_jitter the samples' timing variance, its reference trajectory
// (state.p) and, once the variance has been estimated, the robust weights.
PassSettings joint_pass_settings(const FitSettings& settings, const FitState& state);

// (d) every free slot on x and T̄ weighted by 1/σ̂², σ̂² re-estimated from the residuals until it
// settles (with the samples' timing jitter, by Fisher scoring together with its variance).
// StopReason::model_not_finite when its solution cannot be simulated.
StopReason fit_joint(FitContext& ctx, FitState& state);

// The covariance at the joint solution, written into `result` (covariance, covariance_white,
// sigma, sigma_white, the batch-means check, hac_lags, outliers, residual_rms, noise_sigma):
// one pass at the solution with the final σ̂ gives JᵀWJ and the score's long-run covariance
// (refine/covariance.hpp), Newey–West's, checked by batch means; an estimated delay's σ is added.
struct CovarianceOutcome {
  StopReason stop = StopReason::none;  // cancelled during its passes
  bool definite = false;               // JᵀWJ and the sandwich were positive definite
  TbarRange model_range;               // the model's T̄ over the window at the solution
};
CovarianceOutcome estimate_covariance(FitContext& ctx, const FitState& state, FitResult& result);
// What estimate_covariance publishes that the joint stage's last pass at the solution already
// gives (residual_rms, noise_sigma, hac_lags, `validated` where it was finite): for a fit whose
// covariance waits.
void publish_solution_pass(const FitContext& ctx, const FitState& state, FitResult& result);
// What estimate_covariance's pass carries with Newey–West `lags`, for a stage's trial passes to
// carry too (StageOptions::trial_covariance): the pass a warm refit's joint stage ends on then
// serves as the covariance's.
TrialCovariance covariance_sums(const FitContext& ctx, int lags);

// The verdict on the solution over the T̄ the window saw and the steady T̄ of its largest V² at θ:
// the first check it fails (model_unstable, fast_pole_unresolved,
// covariance_singular, input_delay_at_limit), or StopReason::none.
StopReason verdict(const FitContext& ctx, const FitState& state,
                   const CovarianceOutcome& covariance);

// The staged fit (a) to (d), the covariance and the verdict on a window already prepared
// (refine/voltage_timing.hpp), with the extensions as `settings` asks (`auto` taken as `on`).
FitResult fit_staged(std::span<const WindowSample> prepared, const Vector6& theta_start,
                     const FitSettings& settings);

// A fit whose covariance waits (fit_staged_deferring_covariance): its context and solution, which
// conclude_deferred finishes as conclude() would have.
struct PendingCovariance {
  FitContext ctx;
  FitState state;
};

// fit_staged for a fit the switches' placement will probably replace: where every stage ran, the
// result carries what the placement and a refit read (θ, the noise σ, Newey–West's lags,
// `validated` where the solution's pass was finite, the verdict but for the covariance's
// definiteness) and its covariance's pass waits in `pending`; elsewhere as fit_staged, `pending`
// empty. A covariance the conclusion then finds singular ends the fit there: the shapes fit_staged
// retries after a fit that did not converge are not tried for it.
FitResult fit_staged_deferring_covariance(std::span<const WindowSample> prepared,
                                          const Vector6& theta_start, const FitSettings& settings,
                                          std::optional<PendingCovariance>& pending);

// The covariance and the verdict of a fit whose covariance waited, into `result` (which keeps its
// iterations).
void conclude_deferred(PendingCovariance& pending, FitResult& result);

// FitSettings::extensions with an `auto`: the model with every extension not `off` fitted by the
// stages, then each `auto` one dropped in turn (the joint stage from that solution with it held
// at 0) and left out where Schwarz's BIC (refine/information_criteria.hpp) says it does not earn
// its place. The result is the model chosen, each `auto` extension with the criterion's
// difference (with minus without) that decided. Its two steps follow.
FitResult select_extensions(std::span<const WindowSample> prepared, const Vector6& theta_start,
                            const FitSettings& settings);

// The staged fit with every `auto` extension on; where it does not converge, the model without
// them (the choice then made: none kept).
FitResult fit_extended(std::span<const WindowSample> prepared, const Vector6& theta_start,
                       const FitSettings& settings);

// Whether `fit` converged with every `auto` extension of `settings` in its model (fit_extended's
// extended fit, not its fallback): what the choice starts from.
bool is_extended(const FitResult& fit, const FitSettings& settings);

// How the choice weighs a model. `bic`: Schwarz's criterion. `own_phases`: on a window whose
// switches were placed (refine/switch_placement.hpp) for the model of whichever fit placed them,
// the criterion less the cost phases of the model's own would take off it (placement_decrease): a
// model judged at phases placed for another pays for their misfit, and the term they were placed
// with would be kept for what the phases absorbed.
enum class ExtensionWeighing { bic, own_phases };

// The choice from `extended`, a fit of `prepared` for which is_extended holds: each `auto`
// extension dropped in turn and left out where the model without it converges and is no worse.
FitResult eliminate_extensions(std::span<const WindowSample> prepared, FitResult extended,
                               const FitSettings& settings, ExtensionWeighing weighing);

// The choice made again at `fitted`, a fit of `prepared` whose switches have been placed: from
// `fitted` itself where it is extended, else from the joint stage that frees every `auto`
// extension from its solution (not converged where that does not), weighed `own_phases`.
FitResult reselect_extensions(std::span<const WindowSample> prepared, const FitResult& fitted,
                              const FitSettings& settings);

// The end of a fit whose stages returned `stop`: θ and what the stages estimated into `result`,
// then, when they all ran, the covariance at the solution and the verdict (converged, stop,
// message).
void conclude(FitContext& ctx, const FitState& state, StopReason stop, FitResult& result);

}  // namespace scp::refine

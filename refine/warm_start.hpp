#pragma once
// A warm refit: the daemon refits a sliding window every few seconds, and the previous window's
// solution, shifted to the new window, is already near the new one's. As in moving-horizon
// estimation, the new fit starts from it (θ, the nuisance terms and the noise model as they were,
// the state at the new window's first sample from the previous fit's own trajectory) and runs only
// the joint stage, the covariance and the verdict of the full fit (refine/fit.cpp).
//
// The trajectory is carried by the caller, one sample at a time as the window slides past
// (shift()): the samples between the two windows' first samples leave the window before the next
// fit, and keeping them would double the window's memory.

#include <span>
#include <vector>

#include "refine/fit.hpp"

namespace scp::refine {

// Joint-stage iterations a warm refit may take before it gives way to the full fit: a converged
// neighbour needs one or two.
inline constexpr int kWarmIterations = 5;

// The warm refit's convergence: the Gauss–Newton decrement below this fraction of the cost per
// observation, a step under 0.03 σ of every parameter (the full fit's kDecrementTolerance: 1e-3
// σ). Its solution is within that of the full fit's, well inside the 0.1 σ a refit must agree to,
// and the step that reaches it from a converged neighbour is mostly the last one needed.
inline constexpr double kWarmDecrementTolerance = 1e-3;

// The longest window, as a multiple of the previous fit's, that a warm refit takes: past it, the
// choices it keeps were made on less than half the data (WarmFallback::window_grown). A window
// that slides keeps its length; one that grows from the daemon's start is refitted in full at
// each doubling.
inline constexpr double kWarmWindowGrowth = 2.0;

struct WarmStart {
  FitSettings settings;  // what the previous fit was made with (cancel and warm cleared)
  bool converged = false;
  double t_begin = 0.0, t_end = 0.0;  // the previous window's first and last samples
  Vector6 theta = Vector6::Zero();
  InitialState state = InitialState::Zero();  // the previous fit's model at `at`
  WindowSample at;  // the sample `state` belongs to, as the model reads it (prepared_sample)
  // The nuisance terms at `at` (the ambient's offset moves with its drift), the noise model's
  // variances (x, T̄; the samples' timing, s²) and the voltage's timing as the fit left them.
  Vector3 nuisance = Vector3::Zero();  // x zero, ambient offset, ambient drift
  double sensor_lag = 0.0;             // s
  bool sensor_lag_held = false;        // FitResult::sensor_lag_held
  Vector2 noise_variance = Vector2::Zero();
  double timing_variance = 0.0;
  bool input_delay_estimated = false;
  double input_delay_s = 0.0, input_delay_sigma_s = 0.0, input_delay_sigma_inflation = 1.0;
  VoltageInterval voltage_interval = VoltageInterval::before;
  IntervalEvidence voltage_interval_evidence;     // the warm refit keeps the choice, and its doubt
  Matrix6 interval_covariance = Matrix6::Zero();  // and the doubt's share of the covariance
  SwitchPhase voltage_switches;                   // and the switches' phase
  std::vector<PlacedSwitch> placed_switches;      // and where each placed switch fell
  int hac_lags = 0;  // the previous fit's Newey–West lags (FitResult::hac_lags)
  // The extensions as the fit left them: their coefficients and, for `auto`, which it kept (the
  // warm refit keeps the same model; the choice is made again by the next full fit).
  Extensions extensions;
};

// `settings` with each `auto` extension `on` where `chosen` kept it, else `off`.
FitSettings with_chosen_extensions(const FitSettings& settings, const Extensions& chosen);

// The warm start `fit` leaves at its window's first sample `first` (as recorded), for a fit made
// with `settings`.
WarmStart warm_start(const FitResult& fit, const FitSettings& settings, const WindowSample& first);

// Steps `warm` from its sample, recorded as `from`, to `next`, the sample recorded after it: the
// previous fit's model over that interval (as its window read it), the ambient offset moved by
// its drift. A warm start of a fit that did not converge, or whose trajectory left the finite
// numbers, stays where it is (applicable() declines it either way).
void shift(WarmStart& warm, const WindowSample& from, const WindowSample& next) noexcept;

// WarmFallback::none when `warm` can seed a fit of `window` under `settings`: the previous fit
// converged, under the same settings, and `warm` has been shifted to the window's first sample,
// which the previous window held.
WarmFallback applicable(const WarmStart& warm, std::span<const WindowSample> window,
                        const FitSettings& settings);

// The warm refit of `window` (checked by the caller, as fit() does) from `warm`: the joint stage
// with at most kWarmIterations iterations per round of its noise model, then the covariance and
// the verdict. Switches the previous fit placed keep their places, and the rounds of placement
// follow (the window's new switches placed, the others moved where the new window asks). warm =
// true when it applied, converged and passed; otherwise warm_fallback says why (fit() with
// FitSettings::warm then runs the full fit).
FitResult refit(std::span<const WindowSample> window, const WarmStart& warm,
                const FitSettings& settings);

// Where a joint refit starts, which sets how its stage runs.
enum class RefitStart {
  // anywhere: the full fit's joint stage, its tolerance and a covariance pass of its own
  fit,
  // a converged neighbour's solution (the warm refit): Gauss–Newton's step first, convergence at
  // kWarmDecrementTolerance, the covariance from the pass that shows it
  neighbour,
  // this window's own solution before a small change of its samples (the switches placed anew):
  // Gauss–Newton's step first, the full fit's tolerance, the covariance from the pass that shows
  // convergence where the Newey–West lags the solution's residuals choose are the start's
  same_window,
};

// The joint stage, the covariance and the verdict on a window already prepared
// (refine/voltage_timing.hpp), from `from`'s solution at the window's first sample, with at most
// `max_iterations` per round of the noise model: the end of a fit whose start is known. Returns
// whatever it reached (converged or not, with its residuals where the stage ran).
FitResult joint_refit(std::span<const WindowSample> prepared, const WarmStart& from,
                      const FitSettings& settings, int max_iterations,
                      RefitStart start = RefitStart::fit);

// θ fitted again on the window `fitted` fitted, prepared alike but for a small change of its
// samples (the switches placed anew: refine/switch_placement.hpp): the joint stage from `fitted`'s
// solution (RefitStart::same_window), its model and its choices (extensions, lag held, delay,
// noise model) kept.
FitResult refit_same_window(std::span<const WindowSample> prepared, const FitResult& fitted,
                            const FitSettings& settings);

}  // namespace scp::refine

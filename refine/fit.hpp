#pragma once
// A consistent estimate of θ beside the paper's law: output-error (grey-box prediction-error)
// fitting of the continuous-time SCP model over a window of recorded samples.
//
//   m ẍ + b ẋ + α1 T̄ ẋ + k x = −α2 T̄        Cth dT̄/dt = −λ T̄ + V²/R
//
// The model is simulated from the measured voltage alone (exact discretization per sample
// interval), so the noise on x and T̄ enters only the residuals, never the regressors: unlike least
// squares on filtered noisy regressors (errors-in-variables, biased toward zero), the fit is
// consistent, and (JᵀWJ)⁻¹ is its Cramér–Rao covariance. See docs/numerics.md.
//
// A pure library: no threads, no clock, no I/O, no logging. The daemon owns the worker thread that
// hands it a window (daemon/analysis/refine/).

#include <Eigen/Core>
#include <array>
#include <atomic>
#include <cstddef>
#include <limits>
#include <memory>
#include <span>
#include <vector>

#include "estimator/estimator.hpp"
#include "estimator/types.hpp"
#include "refine/fit_terms.hpp"
#include "refine/stop_reason.hpp"
#include "refine/validation.hpp"
#include "refine/warm_fallback.hpp"

namespace scp::refine {

using estimator::Vector2;
using estimator::Vector6;
using Vector3 = Eigen::Vector3d;
using Matrix6 = Eigen::Matrix<double, 6, 6>;

// One recorded sample. `voltage` is the voltage the plant saw from `voltage_since` until `t`; from
// the previous sample's t until `voltage_since` it saw the previous sample's voltage. A DAC that
// switches exactly at sample instants has voltage_since ≤ the previous t (the usual case: set it
// to the previous t or to −∞). A link whose write lands mid-cycle sets the instant it landed.
struct WindowSample {
  double t = 0.0;                 // s, when x and T were sampled
  double x = 0.0;                 // m
  double tbar = 0.0;              // °C above ambient
  double voltage = 0.0;           // V
  double voltage_since = -1e300;  // s
  // true: the voltage ramps linearly from the previous sample's `voltage` at its t to this one's
  // at t (a first-order hold; voltage_since is then not used), V² quadratic over the interval.
  bool voltage_ramp = false;
  // With voltage_ramp, when finite: the voltage at the interval's midpoint, which makes V² the
  // quadratic through the interval's ends and middle (refine/voltage_timing.hpp takes it from a
  // cubic through four rows of a continuous voltage). NaN: the chord's, V linear.
  double voltage_mid = std::numeric_limits<double>::quiet_NaN();
  // V/s, for a held switch of a continuous voltage (refine/voltage_switches.hpp): how the previous
  // sample's voltage goes on changing until the switch, and how this one's was already changing
  // after it. 0: held flat on both sides (a DAC).
  double slope_before = 0.0, slope_after = 0.0;
  // A, the heater's current at t (the DAQ's measurement, driven by the voltage over the interval
  // ending at t), NaN when not measured. Measured in every sample of a window: the thermal input
  // is the measured power V·I (refine/heater_power.hpp).
  double current = std::numeric_limits<double>::quiet_NaN();
};

// The window's mean sampling period (s): its span over its intervals; NaN with fewer than two
// samples.
inline double mean_sample_period(std::span<const WindowSample> w) noexcept {
  return w.size() > 1 ? (w.back().t - w.front().t) / static_cast<double>(w.size() - 1)
                      : std::numeric_limits<double>::quiet_NaN();
}

// The model's state at the window's first sample: x, ẋ, T̄.
using InitialState = Vector3;

struct WarmStart;  // refine/warm_start.hpp

struct FitSettings {
  int max_iterations = 100;
  // Parameters held at the start value (the daemon's `estimator.known`): they leave the fit and
  // get σ = 0.
  std::array<bool, 6> known{};
  // Residual autocorrelation lags of the Newey–West (Bartlett) covariance; 0 = automatic: the
  // larger of floor(4·(N/100)^(2/9)) and Andrews' AR(1) plug-in from the residuals' lag-one
  // correlation (refine/covariance.hpp). Coloured sensor noise makes the white-noise (JᵀWJ)⁻¹
  // too optimistic.
  int hac_lags = 0;
  // Batches of the batch-means check on the covariance (refine/covariance.hpp,
  // FitResult::sigma_inflation); < 2 turns it off. The default makes each batch of a 300 s window
  // far longer than the mechanical slow pole, and leaves enough of them for a 99 % test to flag a
  // σ well short of the truth (the degrees of freedom on the paper's voltage: docs/numerics.md,
  // "A consistent estimate").
  int covariance_batches = 20;
  // Bounds on the work of one fit, whatever the data: residual passes over the window (each
  // Levenberg–Marquardt trial, each point of the scale search), and model sub-steps in all of them
  // together (2 per sample and pass on average: a stiff θ costs more sub-steps per sample, see
  // refine/model_simulator.hpp). A fit that runs out returns converged = false.
  int max_evaluations = 400;
  // Polled between passes and every kCancelStride samples inside one (refine/residual_pass.hpp):
  // when it reads true the fit returns converged = false, "cancelled", within about a
  // millisecond of simulation. The daemon's worker points it at its stop flag.
  const std::atomic<bool>* cancel = nullptr;
  // > 0: the voltage's timing relative to the samples is known only to within this (s), and a
  // delay d ∈ [−this, this] of every switch is estimated. The common scale of θ1..θ4 (the inertia)
  // is a sub-millisecond lag between heating and motion (the paper's fast pole: 0.8 ms), so x
  // cannot tell it from a delay of the voltage: 150 µs of unmodelled output latency costs θ1..θ4
  // more than 5 % (tests/refine/test_fit.cpp, AnUnmodelledOutputLatencyIsEstimatedFromTemperature),
  // while θ5, θ6 barely notice. T̄ can tell: its response to V² has no fast pole, so d is
  // found from T̄ alone (the thermal stage refitted along d), the rest of the fit uses it, and its
  // uncertainty is added to θ's covariance. 0: the recorded instants are exact (a simulated or
  // sample-synchronous DAC; on noisy T̄ a free d would cost θ1..θ4 more than it could remove).
  double max_input_delay_s = 0.0;
  // true: the samples' instants are known only to within a random error (a link's jitter), whose
  // variance is estimated with the noise variances and which the fit weights out of each
  // sample's residual along the trajectory's direction (PassSettings::timing_variance). On a
  // noise-free link it is most of x's residual (ẋ times the jitter). false: the stamps are
  // exact.
  bool sample_timing_jitter = false;
  // > 0, with sample_timing_jitter: robust weights beyond this many standard deviations
  // (PassSettings::outlier_threshold), for stamps that a load spike displaced far beyond the
  // jitter (a loop thread that ran a millisecond late while the gate saw nothing). 0: every
  // sample counts fully. kOutlierThreshold2d sets aside 1 % of Gaussian samples, and those only a
  // little.
  double outlier_threshold = 0.0;
  // true, with sample_timing_jitter: the voltage's landing instants are stamps of the same
  // jitter as the samples', and the fit filters the state for the error they put into T̄ and,
  // through it, into x (PassSettings::landing_jitter, refine/landing_filter.hpp).
  bool landing_timing_jitter = false;
  // How the voltage varied between samples: held by a DAC (zoh: V² constant over each piece) or
  // continuous (foh: V linear between samples, V² quadratic).
  estimator::VoltageHold voltage_hold = estimator::VoltageHold::zoh;
  // Which interval a row's voltage belongs to (refine/fit_terms.hpp).
  VoltageInterval voltage_interval = VoltageInterval::before;
  // A declared interval (before or after) is weighed against the other as `estimate` would, and
  // the fit says when the data contradict it (IntervalEvidence::contradicted). A declaration is a
  // guess a criterion can refute where the window decides; the fit still uses the declared one.
  bool check_declared_interval = false;
  // With foh: how the voltage varied between the rows (refine/fit_terms.hpp).
  VoltageShape voltage_shape = VoltageShape::linear;
  // The nuisance terms of a real bench, each estimated or fixed (refine/fit_terms.hpp).
  NuisanceSettings nuisance;
  // The model's extensions (refine/fit_terms.hpp), off unless asked for.
  ExtensionSettings extensions;
  // The sensors' white-noise standard deviations (x in m, T̄ in °C) for the validation's
  // noise-ratio tests; ≤ 0: not declared.
  Vector2 declared_noise = Vector2::Zero();
  // Non-null: a refit from the previous window's solution shifted to this window
  // (refine/warm_start.hpp): the joint stage only, from θ, the nuisance terms, the noise model and
  // the trajectory's state as the previous fit left them, then the covariance and the verdict;
  // the full staged fit from `theta_start` when the warm start does not apply or does not
  // converge (FitResult::warm, warm_fallback). Not part of what a warm start compares.
  const WarmStart* warm = nullptr;
  // false: `theta_start`'s common scale of θ1..θ4 is a converged fit's of an overlapping window,
  // and the full fit takes it as it is instead of searching for it (stage (b), whose passes run
  // at up to 30 times the start's stiffness). fit() clears it itself for the full fit a warm
  // refit gives way to when its joint stage did not converge (WarmFallback::not_converged) from
  // a converged warm start and `theta_start` is its θ. Not part of what a warm start compares.
  bool search_scale = true;
};

// √χ²₂(0.99): the radius within which 99 % of a two-channel Gaussian residual falls.
inline constexpr double kOutlierThreshold2d = 3.0349;

struct FitResult {
  bool converged = false;  // the solver met its tolerance and the model is stable at θ
  int iterations = 0;      // solver iterations over all stages, plus the scale search's evaluations
  int evaluations = 0;     // residual passes over the window (FitSettings::max_evaluations)
  // Why the fit ended short of its verdict or which check of the verdict failed; none when
  // every stage ran and the verdict passed (then `message` is the solver's).
  StopReason stop = StopReason::none;
  const char* message = "";  // static string: why it stopped (for logs and the protocol)
  Vector6 theta = Vector6::Zero();
  Vector6 sigma = Vector6::Zero();  // sqrt(diag(covariance)), 0 for known parameters
  // Newey–West (HAC), checked by batch means: honest for coloured residuals too.
  Matrix6 covariance = Matrix6::Zero();
  // (JᵀWJ)⁻¹ with W from the estimated noise variances: right for white sensor noise only.
  Matrix6 covariance_white = Matrix6::Zero();
  Vector6 sigma_white = Vector6::Zero();
  // The batch-means check (FitSettings::covariance_batches): the factor by which it scaled each σ
  // of `covariance` (1: not significantly larger than Newey–West's), the corrected ratio it
  // tested and its degrees of freedom. Above 1 on a live link, rarely on white sensor noise
  // (docs/numerics.md, "Time on a real link"; bench/montecarlo.md).
  Vector6 sigma_inflation = Vector6::Ones();
  Vector6 batch_ratio = Vector6::Zero();  // batch-means variance / Newey–West's, corrected
  Vector6 batch_dof = Vector6::Zero();    // its degrees of freedom
  int hac_lags = 0;  // the Newey–West lags used (FitSettings::hac_lags or the automatic choice)
  InitialState initial_state = InitialState::Zero();
  Vector2 residual_rms = Vector2::Zero();  // x in m, T̄ in °C
  Vector2 noise_sigma = Vector2::Zero();   // estimated sensor noise standard deviation, same units
  double t_begin = 0.0;                    // s, first and last sample of the window fitted
  double t_end = 0.0;
  std::size_t samples = 0;
  // FitSettings::max_input_delay_s: whether the voltage's delay was estimated, the delay (s,
  // positive: the voltage switched later than recorded) and its standard deviation, which
  // `covariance` and `sigma` include.
  bool input_delay_estimated = false;
  double input_delay_s = 0.0;
  double input_delay_sigma_s = 0.0;
  // What the batch-means check on d (refine/delay_batch_means.hpp) scaled its σ by; 1 when the
  // batches did not differ beyond chance.
  double input_delay_sigma_inflation = 1.0;
  // FitSettings::sample_timing_jitter: the estimated RMS error of the samples' instants (s).
  double sample_timing_sigma_s = 0.0;
  // FitSettings::outlier_threshold: the samples the final pass down-weighted. The covariance is
  // the sandwich of the weighted fit, so what they still contribute is counted in σ.
  std::size_t outliers = 0;
  // The voltage interval the fit used: FitSettings::voltage_interval, or the one `estimate` chose
  // (before or after), and how far the data decided it: with `estimate` undetermined, θ1..θ4 are
  // the guessed interval's (refine/voltage_timing.hpp).
  VoltageInterval voltage_interval = VoltageInterval::before;
  IntervalEvidence voltage_interval_evidence;
  // An undetermined interval's share of `covariance` (and so of `sigma`): w·ddᵀ, d the other
  // interval's θ minus this one's, w the other's weight from the criterion (Schwarz's
  // approximation of its posterior probability; refine/interval_averaging.hpp). Zero otherwise.
  Matrix6 interval_covariance = Matrix6::Zero();
  // A smooth voltage's switches and where in their intervals the fit put them (foh, smooth), and
  // where each placed switch fell, for the next window's warm refit (refine/warm_start.hpp).
  SwitchPhase voltage_switches;
  std::vector<PlacedSwitch> placed_switches;
  // The nuisance terms and extensions as the fit left them (refine/fit_terms.hpp).
  Nuisance nuisance;
  // FitSettings estimates the sensor's lag, but this window could not tell it from the thermal
  // block's other terms, and the fit held it at its prior (refine/lag_hold.hpp;
  // nuisance.sensor_lag then reads not estimated).
  bool sensor_lag_held = false;
  Extensions extensions;
  HeaterResistance heater;
  // The model validation of the final pass (refine/validation.hpp); `validated` once it ran.
  ValidationReport validation;
  bool validated = false;
  // The final pass's validator, whose block means a test of more fitted parameters than its
  // samples carried reruns on (the placed switches' phases, refine/fit.cpp); released before
  // refine::fit returns.
  std::shared_ptr<const ResidualValidator> validator;
  // FitSettings::warm: whether this is the warm refit's result, or why the full fit was run
  // instead (its iterations and evaluations then include the warm attempt's).
  bool warm = false;
  WarmFallback warm_fallback = WarmFallback::not_requested;
};

// Fits θ, the initial state and the noise variances to `window` (at least 3 samples, t strictly
// increasing), starting from `theta_start`. Never throws; a window it cannot use returns
// converged = false with the reason in `message`.
FitResult fit(std::span<const WindowSample> window, const Vector6& theta_start,
              const FitSettings& settings = {});

// Cramér–Rao bound of θ for this input (t, voltage, voltage_since of `window`; x and T̄ ignored),
// the true θ and initial state, and white sensor noise of standard deviation noise_sigma (x in m,
// T̄ in °C): the covariance an efficient unbiased estimator reaches. Known parameters as in fit();
// the initial state is a nuisance parameter (estimated alongside, its uncertainty included), and
// so are the nuisance terms `nuisance` does not fix (as fit(): none by default). A channel with
// noise_sigma ≤ 0 is taken as not measured. `truth`: the model's extensions' true coefficients;
// those `extensions` does not leave `off` are estimated alongside too. The sensor's lag is
// nuisance.sensor_lag.value, estimated unless fixed.
Matrix6 cramer_rao_bound(std::span<const WindowSample> window, const Vector6& theta,
                         const InitialState& initial, const Vector2& noise_sigma,
                         const std::array<bool, 6>& known = {},
                         const NuisanceSettings& nuisance = {},
                         const ExtensionSettings& extensions = {}, const Tempcos& truth = {});

// Per block (0 mechanical θ1..θ4, 1 thermal θ5, θ6): the Wald statistic of another estimate θ̂_o
// with claimed standard deviations σ_o against this fit, dᵀ(C_fit + diag(σ_o²))⁻¹d with d = θ̂_o −
// θ̂_fit over the block's free parameters, and its χ² threshold at 0.999 for that many degrees of
// freedom. An estimate whose statistic exceeds the threshold claims a σ its bias does not allow.
struct BiasTest {
  Vector2 statistic = Vector2::Zero();
  Vector2 threshold = Vector2::Zero();
  std::array<bool, 2> biased{};
};
BiasTest test_against(const FitResult& fit, const Vector6& other_theta, const Vector6& other_sigma,
                      const std::array<bool, 6>& known = {});

}  // namespace scp::refine

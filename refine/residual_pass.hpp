#pragma once
// One pass over the window at a parameter vector p: the weighted residuals and, optionally, the
// normal equations of Gauss–Newton accumulated sample by sample. Streaming on purpose: JᵀWJ
// (kParams × kParams) and JᵀWr are summed as the simulation runs, so memory does not grow with
// the window (a 2N × kParams Jacobian of a 300 s window at 1 kHz would be tens of megabytes).

#include <array>
#include <atomic>
#include <optional>
#include <span>
#include <vector>

#include "refine/model_simulator.hpp"

namespace scp::refine {

class ResidualValidator;

struct PassSettings {
  // 1/σ² for x and T̄; 0 leaves that channel out of the fit.
  std::array<double, 2> weight{1.0, 1.0};
  bool jacobian = true;
  // Simulate T̄ only (the thermal stage: θ1..θ4, x0, ẋ0 play no part).
  bool thermal_only = false;
  // Jacobian passes: also the sensitivities to the extensions' slots (a fit that estimates one;
  // without, their columns of J are left 0). The simulation runs with p's extensions either way.
  bool extensions = false;
  // Jacobian passes: also the sensitivity to the sensor's lag (refine/sensor_lag.hpp), whose
  // reading the pass applies wherever p's lag is not 0.
  bool sensor_lag = false;
  // > 0: also accumulate the Bartlett long-run covariance of the score with this bandwidth
  // (lags + 1), for the Newey–West covariance.
  int hac_bandwidth = 0;
  // > 1: also sum the score and the information over this many contiguous batches of equal
  // sample count (PassResult::batch_scores, batch_information), for the batch-means check.
  int batches = 0;
  // > 0: give up (finite = false, too_stiff = true) once the simulation has taken more sub-steps
  // than this: a model stiffer than the caller can afford (refine/budget.hpp bounds it by what the
  // window's sampling can show), not a reason to spend minutes on one pass.
  long max_substeps = 0;
  // Polled every kCancelStride samples: when it reads true the pass gives up (cancelled = true).
  const std::atomic<bool>* cancel = nullptr;
  // s: every voltage switch this much later than recorded (pieces_between).
  double input_delay = 0.0;
  // > 0 (s²): each sample was taken at an instant off its stamp by a random error of this
  // variance, the same for x and T̄ (one transaction read both). Its residual then has the
  // covariance Σ + s·g gᵀ, g = (ẋ, dT̄/dt) the trajectory's velocity at the sample: the fit
  // weights each sample by the inverse (Sherman–Morrison), so the component along g, which a
  // shift in time explains, counts less (errors in the time variable, as orthogonal distance
  // regression treats them). g comes from `timing_reference`, not from p, so that the weights
  // large). Jacobian passes only; `timing` turns the weights and their statistics on (also at
  // variance 0, where the weights are the plain ones).
  bool timing = false;
  double timing_variance = 0.0;
  ParamVector timing_reference = ParamVector::Zero();
  // > 0 (with `timing`): robust weights. A sample whose residual at `timing_reference`, measured
  // in its own standard deviations m = √(rᵀWr) (W as above), exceeds this threshold a counts less
  // (Hampel's three-part weights: a/m up to 2a, down to 0 at 3a): a stamp a load spike displaced
  // by milliseconds (m ~ 50 where the jitter is tens of µs) does not pull the fit. Fixed by the
  // reference like the timing weights, so every pass of one round minimizes the same cost.
  double outlier_threshold = 0.0;
  // With `timing`: the voltage's landing instants (WindowSample::voltage_since) carry a random
  // error of the same variance as the samples' (timing_variance: both are stamps of one link's
  // transactions). A landing δ off puts θ6·ΔV²·δ into T̄ that the model does not have, and it
  // reaches x through T̄ for seconds: process noise on the thermal state. The pass then runs a
  // Kalman filter on [x, ẋ, T̄] (refine/landing_filter.hpp; P propagated along the reference
  // trajectory, each landing adding s·v vᵀ, v its effect carried to the sample), corrects the
  // simulated state with T̄'s innovation (gains P e₃/(P_T̄T̄ + σT̄² + s·ġT̄²)) and weights each
  // sample's residuals by their covariance Σ + P + s·g gᵀ: prediction error on T̄, and on x
  // through T̄'s innovations only.
  bool landing_jitter = false;
  // Jacobian passes: feeds every sample's residual, model outputs and sensitivities to this
  // validator (refine/validation.hpp), so that the fit's final pass validates the model at no
  // extra simulation. With the landing filter, the residuals are its innovations.
  ResidualValidator* validator = nullptr;
};

// Samples between two polls of PassSettings::cancel: ~1 ms of simulation.
inline constexpr std::size_t kCancelStride = 1024;

// JᵀWJ and JᵀWr of x's rows ([0]) and of T̄'s ([1]), whose sums are PassResult's jtwj and jtwr.
struct ChannelSums {
  std::array<ParamMatrix, 2> jtwj{ParamMatrix::Zero(), ParamMatrix::Zero()};
  std::array<ParamVector, 2> jtwr{ParamVector::Zero(), ParamVector::Zero()};
};

struct PassResult {
  bool finite = false;
  double cost = 0.0;  // Σ_k Σ_c w_c r_ck², r = measured − model
  ParamMatrix jtwj = ParamMatrix::Zero();
  ParamVector jtwr = ParamVector::Zero();
  std::array<double, 2> rss{};   // Σ r² per channel (unweighted)
  std::array<double, 2> lag1{};  // Σ r_k·r_{k−1} per channel: the residuals' colour
  ParamMatrix long_run =
      ParamMatrix::Zero();  // Σ_{|l|<B} (1 − |l|/B)·Σ_k s_k s_{k+l}ᵀ, s_k = J_kᵀW r_k
  // With PassSettings::batches = K: per batch b, the score g_b = Σ_{k∈b} s_k and the information
  // H_b = Σ_{k∈b} J_kᵀW J_k (its share of jtwj) and the cost (its share of `cost`); empty
  // otherwise.
  std::vector<ParamVector> batch_scores;
  std::vector<ParamMatrix> batch_information;
  std::vector<double> batch_costs;
  double tbar_min = 0.0, tbar_max = 0.0;  // range of the model's T̄ (damping positivity check)
  long substeps = 0;                      // model sub-steps simulated (the pass's cost)
  bool too_stiff = false;                 // stopped at PassSettings::max_substeps
  bool cancelled = false;                 // stopped at PassSettings::cancel
  // With PassSettings::timing, for the re-estimation of the variances v = (σx², σT̄², s) by Fisher
  // scoring (refine/joint_stage.cpp): per sample, C = Σ + s·g gᵀ, W = C⁻¹, D_j = ∂C/∂v_j, the score
  // ½(rᵀW D_j W r − tr(W D_j)) and the information ½·tr(W D_i W D_j), summed.
  Eigen::Vector3d variance_score = Eigen::Vector3d::Zero();
  Eigen::Matrix3d variance_information = Eigen::Matrix3d::Zero();
  std::array<double, 2> speed_squares{};  // Σ gx², Σ gT̄² (the timing error's share per channel)
  std::size_t outliers = 0;  // with PassSettings::outlier_threshold: samples down-weighted
  // Jacobian passes without the timing weights, whose weight matrix is diagonal: each channel's
  // share, from which the pass at other channel weights follows (reweighted()).
  std::optional<ChannelSums> channels;
};

PassResult residual_pass(std::span<const WindowSample> window, const ParamVector& p,
                         const PassSettings& settings);

// The pass at the same p with each channel weighted to[c] instead of from[c] (PassSettings::
// weight): its cost, JᵀWJ and JᵀWr, what a new pass would sum up to rounding. Without the long-run
// and batch sums; nothing where the pass did not keep its channels apart or left out a channel
// `to` weights.
std::optional<PassResult> reweighted(const PassResult& pass, const std::array<double, 2>& from,
                                     const std::array<double, 2>& to);

}  // namespace scp::refine

// The covariance at the joint solution (refine/stages.hpp: estimate_covariance).
#include <algorithm>
#include <cmath>
#include <memory>

#include "refine/covariance.hpp"
#include "refine/stages.hpp"
#include "refine/validate_fit.hpp"
#include "refine/validation.hpp"

namespace scp::refine {

namespace {

// Newey–West's lags: the caller's (at most a quarter of the window, which would leave too few
// batches to average), or the automatic choice from the joint pass's lag-one correlations.
int newey_west_lags(std::size_t n, int asked, const PassResult& joint) {
  const double rho_x = joint.rss[0] > 0.0 ? joint.lag1[0] / joint.rss[0] : 0.0;
  const double rho_t = joint.rss[1] > 0.0 ? joint.lag1[1] / joint.rss[1] : 0.0;
  const int max_lags = static_cast<int>(std::max<std::size_t>(1, n / 4));
  return asked > 0 ? std::min(asked, max_lags) : automatic_hac_lags(n, std::max(rho_x, rho_t));
}

int newey_west_lags(const FitContext& ctx, const PassResult& joint) {
  return newey_west_lags(ctx.window.size(), ctx.settings.hac_lags, joint);
}

// What σ_d does to θ: the Gauss–Newton step from the solution to the fit at d̂ + σ_d (one pass),
// added to both covariances as an independent error (the delay comes from T̄'s fit, whose noise
// the rest of the covariance counts only through θ5, θ6).
StopReason add_input_delay_error(FitContext& ctx, const FitState& state, PassSettings ps,
                                 const PassResult& at_solution, const ParamMatrix& white,
                                 FitResult& result) {
  ps.hac_bandwidth = 0;
  ctx.budget.set_input_delay(state.delay.delay + state.delay.sigma);
  const PassResult shifted = ctx.budget.pass(ctx.window, state.p, ps);
  ctx.budget.set_input_delay(state.delay.delay);
  if (shifted.cancelled) return StopReason::cancelled;
  if (shifted.finite) {
    const Vector6 shift = (white * (shifted.jtwr - at_solution.jtwr)).head<kThetaSize>();
    result.covariance_white += shift * shift.transpose();
    result.covariance += shift * shift.transpose();
  }
  return StopReason::none;
}

// The residuals' RMS and the sensor noise alone: with the timing jitter estimated, its variance
// components; otherwise RSS/(N − p) per channel.
void publish_residuals(const FitContext& ctx, const FitState& state, const PassResult& pass,
                       FitResult& result) {
  const std::size_t n = ctx.window.size();
  const std::array<std::size_t, 2> parameters = parameters_per_channel(fit_slots(ctx.settings));
  result.residual_rms = Vector2(std::sqrt(pass.rss[0] / static_cast<double>(n)),
                                std::sqrt(pass.rss[1] / static_cast<double>(n)));
  result.noise_sigma = ctx.settings.sample_timing_jitter
                           ? Vector2(std::sqrt(state.noise.x), std::sqrt(state.noise.tbar))
                           : Vector2(std::sqrt(pass.rss[0] / dof(n, parameters[0])),
                                     std::sqrt(pass.rss[1] / dof(n, parameters[1])));
}

// The joint stage ended on a trial pass that carried the covariance's sums (StageOptions::
// trial_covariance) at the solution: that pass is the covariance's. Its weights are those of the
// joint stage's last round, which the noise model's re-estimate then confirmed within its
// settling tolerance (refine/joint_stage.cpp).
bool joint_pass_has_the_sums(const FitContext& ctx, const FitState& state) {
  const TrialCovariance* sums = ctx.joint_options.trial_covariance;
  if (sums == nullptr || state.joint.validator == nullptr || !state.joint.pass.finite ||
      state.joint.p != state.p)
    return false;
  return !sums->only_at_own_lags || sums->chooses_own_lags(state.joint.pass);
}

}  // namespace

TrialCovariance covariance_sums(const FitContext& ctx, int lags) {
  TrialCovariance sums;
  sums.hac_bandwidth = lags + 1;
  sums.batches = ctx.settings.covariance_batches;
  sums.lags_of = [n = ctx.window.size(), asked = ctx.settings.hac_lags](const PassResult& pass) {
    return newey_west_lags(n, asked, pass);
  };
  const FreeMask free = fit_slots(ctx.settings);
  ValidationSettings vs;
  vs.declared_noise = ctx.settings.declared_noise;
  sums.validator = [window = ctx.window, free, vs](const ParamVector& p) {
    const Vector6 theta = theta_of(p);
    const AmbientError ambient{p[kAmbientOffsetSlot], p[kAmbientDriftSlot]};
    return std::make_shared<ResidualValidator>(
        theta, validation_settings(window, theta, free, vs, ambient));
  };
  return sums;
}

void publish_solution_pass(const FitContext& ctx, const FitState& state, FitResult& result) {
  const PassResult& pass = state.joint.pass;
  result.hac_lags = newey_west_lags(ctx, pass);
  result.validated = pass.finite;
  if (pass.finite) publish_residuals(ctx, state, pass, result);
}

CovarianceOutcome estimate_covariance(FitContext& ctx, const FitState& state, FitResult& result) {
  CovarianceOutcome out;
  const bool reuse = joint_pass_has_the_sums(ctx, state);
  const int lags = reuse ? ctx.joint_options.trial_covariance->hac_bandwidth - 1
                         : newey_west_lags(ctx, state.joint.pass);
  const TrialCovariance sums = covariance_sums(ctx, lags);
  const FreeMask free = fit_slots(ctx.settings);
  PassSettings ps = joint_pass_settings(ctx.settings, state);
  ps.hac_bandwidth = sums.hac_bandwidth;
  ps.batches = sums.batches;
  const std::shared_ptr<ResidualValidator> validator =
      reuse ? state.joint.validator : sums.validator(state.p);
  ps.validator = validator.get();
  const PassResult pass = reuse ? state.joint.pass : ctx.budget.pass(ctx.window, state.p, ps);
  result.evaluations = ctx.budget.evaluations();
  if (pass.cancelled) {
    out.stop = StopReason::cancelled;
    return out;
  }
  if (pass.finite) {
    result.validation = validator->finish();
    result.validator = validator;
    result.validated = true;
  }
  ParamMatrix white = ParamMatrix::Zero(), hac = ParamMatrix::Zero();
  const bool white_ok = pass.finite && inverse_on_free(pass.jtwj, free, white);
  out.definite = white_ok && sandwich_on_free(pass.jtwj, pass.long_run, free, hac);
  out.model_range = {pass.tbar_min, pass.tbar_max};
  result.hac_lags = lags;
  result.outliers = pass.outliers;
  result.covariance_white = white.topLeftCorner<kThetaSize, kThetaSize>();
  if (out.definite) {
    const BatchMeansCheck check =
        check_against_batch_means(hac, pass.jtwj, pass.batch_scores, pass.batch_information, free);
    result.sigma_inflation = check.factor.head<kThetaSize>();
    result.batch_ratio = check.ratio.head<kThetaSize>();
    result.batch_dof = check.dof.head<kThetaSize>();
  }
  result.covariance = hac.topLeftCorner<kThetaSize, kThetaSize>();
  if (state.delay.ok && white_ok && state.delay.sigma > 0.0) {
    out.stop = add_input_delay_error(ctx, state, ps, pass, white, result);
    if (out.stop != StopReason::none) return out;
  }
  const auto sigma_of = [&hac](int slot) { return std::sqrt(std::max(hac(slot, slot), 0.0)); };
  result.nuisance.x_zero.sigma = free[kXZeroSlot] ? sigma_of(kXZeroSlot) : 0.0;
  result.nuisance.ambient_offset.sigma =
      free[kAmbientOffsetSlot] ? sigma_of(kAmbientOffsetSlot) : 0.0;
  result.nuisance.ambient_drift.sigma = free[kAmbientDriftSlot] ? sigma_of(kAmbientDriftSlot) : 0.0;
  result.nuisance.sensor_lag.sigma = free[kSensorLagSlot] ? sigma_of(kSensorLagSlot) : 0.0;
  for (const ExtensionSlot& e : kExtensionTable)
    (result.extensions.*e.estimate).sigma = free[e.slot] ? sigma_of(e.slot) : 0.0;
  result.sigma_white = result.covariance_white.diagonal().cwiseMax(0.0).cwiseSqrt();
  result.sigma = result.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  publish_residuals(ctx, state, pass, result);
  return out;
}

}  // namespace scp::refine

// Stage (d) of the fit (refine/stages.hpp): every free slot on both channels, with the noise
// model's variances re-estimated between Levenberg–Marquardt runs until they settle.
#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <optional>

#include "refine/stages.hpp"

namespace scp::refine {

namespace {

// A variance moved by less than this fraction since the last round: settled.
constexpr double kSettled = 0.02;

// σ̂² = RSS/(N − p) per channel, p the free slots acting on it, never below the floor. Returns
// whether both settled.
bool reestimate_variances(const FitContext& ctx, const PassResult& pass,
                          const std::array<std::size_t, 2>& parameters, NoiseVariances& noise) {
  const std::size_t n = ctx.window.size();
  const double var_x = std::max(pass.rss[0] / dof(n, parameters[0]), ctx.variance_floor[0]);
  const double var_t = std::max(pass.rss[1] / dof(n, parameters[1]), ctx.variance_floor[1]);
  const bool settled =
      std::abs(var_x / noise.x - 1.0) < kSettled && std::abs(var_t / noise.tbar - 1.0) < kSettled;
  noise.x = var_x;
  noise.tbar = var_t;
  return settled;
}

// With the samples' timing jitter (FitSettings::sample_timing_jitter): v = (σx², σT̄², s) by one
// step of Fisher scoring from the pass's score and information (refine/residual_pass.hpp),
// starting from s = 0 (the first step is then the moment estimate). EM would crawl toward a noise
// variance near 0 (noise-free sensors), halving it each round. Returns whether v settled.
bool rescore_variances(const FitContext& ctx, const PassResult& pass, NoiseVariances& noise) {
  const Eigen::Vector3d v(noise.x, noise.tbar, noise.timing);
  const Eigen::Vector3d step = pass.variance_information.ldlt().solve(pass.variance_score);
  Eigen::Vector3d next = v;
  if (step.allFinite()) next += step;
  // A step can overshoot toward 0: at most a factor 10 down per round, never below the floors.
  const double var_x = std::max({next[0], 0.1 * noise.x, ctx.variance_floor[0]});
  const double var_t = std::max({next[1], 0.1 * noise.tbar, ctx.variance_floor[1]});
  const double s = std::max({next[2], 0.1 * noise.timing, 0.0});
  // A noise variance below 1 % of what the timing error puts into its channel no longer moves
  // the weights (noise-free sensors: it wanders near its floor).
  const auto variance_settled = [&](double before, double after, std::size_t channel) {
    const double timing_share =
        s * pass.speed_squares[channel] / static_cast<double>(ctx.window.size());
    return std::abs(after / before - 1.0) < kSettled ||
           std::max(before, after) < 0.01 * timing_share;
  };
  bool settled = variance_settled(noise.x, var_x, 0) && variance_settled(noise.tbar, var_t, 1) &&
                 std::abs(s - noise.timing) <= kSettled * std::max(s, noise.timing);
  noise.timing = s;
  // The first round with robust weights changes the cost: not settled yet.
  if (!noise.timing_estimated && ctx.settings.outlier_threshold > 0.0) settled = false;
  noise.timing_estimated = true;
  noise.x = var_x;
  noise.tbar = var_t;
  return settled;
}

}  // namespace

PassSettings joint_pass_settings(const FitSettings& settings, const FitState& state) {
  PassSettings ps;
  ps.weight = {1.0 / state.noise.x, 1.0 / state.noise.tbar};
  carry_optional_slots(settings, ps);
  const bool timing = settings.sample_timing_jitter;
  ps.timing = timing;
  ps.timing_variance = state.noise.timing;
  ps.timing_reference = state.p;
  // Robust weights only once the timing variance is estimated: before that every sample with a
  // large velocity would look like an outlier.
  if (timing && state.noise.timing_estimated) ps.outlier_threshold = settings.outlier_threshold;
  ps.landing_jitter = timing && settings.landing_timing_jitter;
  return ps;
}

StopReason fit_joint(FitContext& ctx, FitState& state) {
  const FreeMask free = fit_slots(ctx.settings);
  const std::array<std::size_t, 2> parameters = parameters_per_channel(free);
  const bool timing = ctx.settings.sample_timing_jitter;
  // With the timing variance to estimate too, more rounds: it starts from 0.
  const int rounds = timing ? 8 : 4;
  // The last round's pass at its solution, at the weights of the variances it re-estimated: the
  // next round's start, whose pass would sum the same (the one-step rule's accepted start mixes
  // two passes and is not reused).
  std::optional<PassResult> start;
  const bool reuse_start = !(ctx.joint_options.one_step_tolerance > 0.0);
  for (int round = 0; round < rounds; ++round) {
    StageOptions options = ctx.joint_options;
    options.start_pass = start ? &*start : nullptr;
    const PassSettings ps = joint_pass_settings(ctx.settings, state);
    state.joint = run_stage(ctx.window, Coordinates(free, state.p), ps, ctx.max_iterations,
                            ctx.budget, state.range, options);
    state.iterations += state.joint.iterations;
    if (state.joint.pass.finite) state.p = state.joint.p;
    if (state.joint.stopped) return ctx.budget.stop();
    if (!state.joint.pass.finite) break;
    const bool settled = timing
                             ? rescore_variances(ctx, state.joint.pass, state.noise)
                             : reestimate_variances(ctx, state.joint.pass, parameters, state.noise);
    if (settled) break;
    if (reuse_start)
      start =
          reweighted(state.joint.pass, ps.weight, joint_pass_settings(ctx.settings, state).weight);
  }
  state.sample_timing_sigma_s = std::sqrt(state.noise.timing);
  if (!state.joint.pass.finite || !state.p.allFinite()) return StopReason::model_not_finite;
  return StopReason::none;
}

}  // namespace scp::refine

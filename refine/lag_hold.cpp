// The sensor's lag held where the window cannot determine it (refine/stages.hpp:
// hold_undetermined_lag; refine/lag_hold.hpp).
//
// In a window short against the excitation's slow period (the paper's 167 s), T̄ is a smooth arc,
// and a lag (the reading is T̄ − τs·dT̄/dt to first order) is nearly a combination of T̄0, the
// ambient's offset and drift and θ5: its σ with those estimated beside it is many times its σ
// were they known. The joint stage then follows that valley, together with the common scale of
// θ1..θ4 (a sub-millisecond lag between heating and motion), for tens of iterations to a lag
// within its σ of where it started. Held at its prior until the window separates it, or unless
// it differs from that prior by more than the window's noise can explain (a real lag of tenths of
// a second shows in the shortest window).
#include "refine/lag_hold.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>

#include "refine/delay_differences.hpp"
#include "refine/input_delay.hpp"
#include "refine/stages.hpp"

namespace scp::refine {

namespace {

// The normal equations over c's slots, and with `delay` present the delay's row and column after
// them; `gradient` the matching JᵀWr.
void normal_equations(const Coordinates& c, const PassResult& pass, const DelayCoordinate& delay,
                      Eigen::MatrixXd& normal, Eigen::VectorXd& gradient) {
  const Eigen::MatrixXd t = c.jacobian();
  const Eigen::Index n = c.size(), size = n + (delay.present ? 1 : 0);
  normal.setZero(size, size);
  gradient.setZero(size);
  normal.topLeftCorner(n, n) = t.transpose() * pass.jtwj * t;
  gradient.head(n) = t.transpose() * pass.jtwr;
  if (!delay.present) return;
  const Eigen::VectorXd cross = t.transpose() * delay.cross;
  normal.block(0, n, n, 1) = cross;
  normal.block(n, 0, 1, n) = cross.transpose();
  normal(n, n) = delay.information;
  gradient[n] = delay.score;
}

}  // namespace

LagJudgement judge_sensor_lag(const Coordinates& c, const PassResult& pass, double tbar_variance,
                              double held, const DelayCoordinate& delay) {
  LagJudgement j;
  Eigen::Index lag = -1;
  for (Eigen::Index i = 0; i < c.size(); ++i)
    if (c.index[static_cast<std::size_t>(i)] == kSensorLagSlot) lag = i;
  if (lag < 0 || !pass.finite) return j;
  Eigen::MatrixXd normal;
  Eigen::VectorXd gradient;
  normal_equations(c, pass, delay, normal, gradient);
  // Beside the delay, equations that cannot be solved are a lag the delay stands for: confounded
  // so closely that the differences' rounding leaves their matrix indefinite.
  j.determined = !delay.present;
  if (!normal.allFinite() || !gradient.allFinite()) return j;
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(normal);
  if (ldlt.info() != Eigen::Success || (delay.present && !ldlt.isPositive())) return j;
  Eigen::VectorXd unit = Eigen::VectorXd::Zero(normal.rows());
  unit[lag] = 1.0;
  // (N⁻¹)_ll: the lag's variance (in units of T̄'s noise variance) with the others estimated.
  const double inverse_ll = ldlt.solve(unit)[lag];
  const double step = ldlt.solve(gradient)[lag];
  if (!(inverse_ll > 0.0) || !std::isfinite(step)) return j;
  j.estimate = c.base[kSensorLagSlot] + step;
  j.sigma = std::sqrt(tbar_variance * inverse_ll);
  j.inflation = std::sqrt(normal(lag, lag) * inverse_ll);
  // A lag no longer than the delay's range is what the delay already stands for.
  j.determined = j.inflation <= kLagConfounding ||
                 std::abs(j.estimate - held) > kLagSignificance * j.sigma + delay.range;
  return j;
}

LagEvidence lag_evidence(FitContext& ctx, const ParamVector& p, const PassResult* at_p) {
  LagEvidence e;
  const PassSettings ps = thermal_pass_settings(ctx.settings);
  const double limit = ctx.settings.max_input_delay_s;
  const double lowest = -earliest_switch_delay(ctx.window, limit);
  const double highest = latest_switch_delay(ctx.window, limit);
  const double d0 = ctx.budget.input_delay();
  // h: far below the sampling, where T̄ is linear in d (a switch moves within its interval).
  const double h = std::min(1e-5, 0.25 * (highest - lowest));
  if (!(limit > 0.0) || !(h > 0.0)) {
    e.pass = at_p != nullptr ? *at_p : ctx.budget.pass(ctx.window, p, ps);
    e.stop = e.pass.cancelled ? StopReason::cancelled : StopReason::none;
    return e;
  }
  const double centre = std::clamp(d0, lowest + h, highest - h);
  const auto pass_at = [&](double d) {
    ctx.budget.set_input_delay(d);
    return ctx.budget.pass(ctx.window, p, ps);
  };
  const PassResult below = pass_at(centre - h), above = pass_at(centre + h);
  e.pass = centre == d0 && at_p != nullptr ? *at_p : pass_at(centre);
  ctx.budget.set_input_delay(d0);
  if (below.cancelled || above.cancelled || e.pass.cancelled) {
    e.stop = StopReason::cancelled;
    return e;
  }
  if (!below.finite || !above.finite || !e.pass.finite) return e;
  const DelayDifferences d =
      delay_differences(below.cost, e.pass.cost, above.cost, below.jtwr, above.jtwr, h);
  e.delay = {.present = true,
             .cross = d.cross,
             .information = d.information,
             .score = d.score,
             .range = limit};
  return e;
}

void hold_sensor_lag(FitContext& ctx, FitState& state, double value) {
  ctx.settings.nuisance.sensor_lag = {.fixed = true, .value = value};
  state.p[kSensorLagSlot] = value;
  state.sensor_lag_held = true;
}

StopReason hold_undetermined_lag(FitContext& ctx, FitState& state) {
  if (ctx.settings.nuisance.sensor_lag.fixed) return StopReason::none;
  const Coordinates c(thermal_slots(ctx.settings), state.p);
  const LagEvidence e = lag_evidence(ctx, state.p, &state.thermal);
  if (e.stop != StopReason::none) return e.stop;
  constexpr double kPrior = 0.0;  // no lag: where an estimated lag starts (set_nuisance_start)
  if (judge_sensor_lag(c, e.pass, state.noise.tbar, kPrior, e.delay).determined)
    return StopReason::none;
  hold_sensor_lag(ctx, state, kPrior);
  return fit_thermal(ctx, state);
}

StopReason judge_held_lag(FitContext& ctx, FitState& state, double held) {
  if (ctx.settings.nuisance.sensor_lag.fixed) return StopReason::none;
  state.p[kSensorLagSlot] = held;
  const Coordinates c(thermal_slots(ctx.settings), state.p);
  const LagEvidence e = lag_evidence(ctx, state.p, nullptr);
  if (e.stop != StopReason::none) return e.stop;
  if (!judge_sensor_lag(c, e.pass, state.noise.tbar, held, e.delay).determined)
    hold_sensor_lag(ctx, state, held);
  return StopReason::none;
}

}  // namespace scp::refine

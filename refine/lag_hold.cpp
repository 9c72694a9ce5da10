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
#include <cmath>

#include "refine/stages.hpp"

namespace scp::refine {

LagJudgement judge_sensor_lag(const Coordinates& c, const PassResult& pass, double tbar_variance,
                              double held) {
  LagJudgement j;
  Eigen::Index lag = -1;
  for (Eigen::Index i = 0; i < c.size(); ++i)
    if (c.index[static_cast<std::size_t>(i)] == kSensorLagSlot) lag = i;
  if (lag < 0 || !pass.finite) return j;
  const Eigen::MatrixXd t = c.jacobian();
  const Eigen::MatrixXd normal = t.transpose() * pass.jtwj * t;
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(normal);
  if (ldlt.info() != Eigen::Success) return j;
  Eigen::VectorXd unit = Eigen::VectorXd::Zero(c.size());
  unit[lag] = 1.0;
  // (N⁻¹)_ll: the lag's variance (in units of T̄'s noise variance) with the others estimated.
  const double inverse_ll = ldlt.solve(unit)[lag];
  const double step = ldlt.solve(t.transpose() * pass.jtwr)[lag];
  if (!(inverse_ll > 0.0) || !std::isfinite(step)) return j;
  j.estimate = c.base[kSensorLagSlot] + step;
  j.sigma = std::sqrt(tbar_variance * inverse_ll);
  j.inflation = std::sqrt(normal(lag, lag) * inverse_ll);
  j.determined =
      j.inflation <= kLagConfounding || std::abs(j.estimate - held) > kLagSignificance * j.sigma;
  return j;
}

void hold_sensor_lag(FitContext& ctx, FitState& state, double value) {
  ctx.settings.nuisance.sensor_lag = {.fixed = true, .value = value};
  state.p[kSensorLagSlot] = value;
  state.sensor_lag_held = true;
}

StopReason hold_undetermined_lag(FitContext& ctx, FitState& state) {
  if (ctx.settings.nuisance.sensor_lag.fixed) return StopReason::none;
  const Coordinates c(thermal_slots(ctx.settings), state.p);
  constexpr double kPrior = 0.0;  // no lag: where an estimated lag starts (set_nuisance_start)
  if (judge_sensor_lag(c, state.thermal, state.noise.tbar, kPrior).determined)
    return StopReason::none;
  hold_sensor_lag(ctx, state, kPrior);
  return fit_thermal(ctx, state);
}

StopReason judge_held_lag(FitContext& ctx, FitState& state, double held) {
  if (ctx.settings.nuisance.sensor_lag.fixed) return StopReason::none;
  state.p[kSensorLagSlot] = held;
  const Coordinates c(thermal_slots(ctx.settings), state.p);
  const PassResult pass = ctx.budget.pass(ctx.window, state.p, thermal_pass_settings(ctx.settings));
  if (pass.cancelled) return StopReason::cancelled;
  if (!judge_sensor_lag(c, pass, state.noise.tbar, held).determined)
    hold_sensor_lag(ctx, state, held);
  return StopReason::none;
}

}  // namespace scp::refine

#include "estimator/estimator.hpp"

#include <algorithm>
#include <cmath>

#include "estimator/config_check.hpp"
#include "estimator/held_lag.hpp"

namespace scp::estimator {
namespace {

double mech_forgetting(const EstimatorConfig& c) {
  return c.forgetting_mechanical > 0.0 ? c.forgetting_mechanical : c.forgetting;
}

BlockRls<4>::Settings mech_settings(const EstimatorConfig& c) {
  BlockRls<4>::Settings s;
  s.forgetting = mech_forgetting(c);
  s.p0 = c.p0;
  s.p_max = c.p_max;
  s.beta = c.beta;
  s.scale = c.scale.head<4>();
  s.theta0 = c.theta0.head<4>();
  for (int i = 0; i < 4; ++i) s.free(i) = c.known[static_cast<std::size_t>(i)] ? 0.0 : 1.0;
  return s;
}

BlockRls<2>::Settings thermal_settings(const EstimatorConfig& c) {
  BlockRls<2>::Settings s;
  s.forgetting = c.forgetting;
  s.p0 = c.p0;
  s.p_max = c.p_max;
  s.beta = c.beta;
  s.scale = c.scale.tail<2>();
  s.theta0 = c.theta0.tail<2>();
  for (int i = 0; i < 2; ++i) s.free(i) = c.known[static_cast<std::size_t>(4 + i)] ? 0.0 : 1.0;
  return s;
}

const EstimatorConfig& validated(const EstimatorConfig& c) {
  validate_config(c);
  return c;
}

// Filter inputs: the non-zero entries of W, eq. (6): row 1 [−ẋ, −T̄ẋ, −x, −T̄], row 2 [−T̄, V²].
Vector6 filter_inputs(const Measurement& m) noexcept {
  Vector6 u;
  u << -m.xdot, -m.tbar * m.xdot, -m.x, -m.tbar, -m.tbar, m.voltage * m.voltage;
  return u;
}

// Symmetric within a relative tolerance and positive definite.
template <typename Mat>
bool symmetric_positive_definite(const Mat& r) noexcept {
  if (!r.allFinite()) return false;
  const double tol = 1e-9 * r.cwiseAbs().maxCoeff();
  if (!((r - r.transpose()).cwiseAbs().maxCoeff() <= tol)) return false;
  Eigen::LLT<Mat> llt(0.5 * (r + r.transpose()));
  return llt.info() == Eigen::Success;
}

}  // namespace

const char* to_string(UpdateOutcome outcome) noexcept {
  switch (outcome) {
    case UpdateOutcome::applied:
      return "applied";
    case UpdateOutcome::initialized:
      return "initialized";
    case UpdateOutcome::skipped_nonfinite:
      return "skipped_nonfinite";
    case UpdateOutcome::skipped_range:
      return "skipped_range";
    case UpdateOutcome::skipped_time:
      return "skipped_time";
    case UpdateOutcome::filters_restarted:
      return "filters_restarted";
  }
  return "unknown";
}

Estimator::Estimator(const EstimatorConfig& config)
    : config_(validated(config)), mech_(mech_settings(config)), thermal_(thermal_settings(config)) {
  reset();
}

void Estimator::reset() noexcept {
  mech_.reset();
  thermal_.reset();
  wf_.setZero();
  p_.setZero();
  u_prev_.setZero();
  v_prev_.setZero();
  t_prev_ = 0.0;
  filters_running_ = false;
  h_cached_ = -1.0;
  estimate_ = Estimate{};
  refresh_estimate();
}

void Estimator::start_filters(const Measurement& m) noexcept {
  // eq. (15) with W_f(0) = 0, and p = −βv so that a_f = p + βv = 0 (eq. (10), a_f(0) = 0).
  wf_.setZero();
  v_prev_ << m.xdot, m.tbar;
  p_ = -config_.beta * v_prev_;
  u_prev_ = filter_inputs(m);
  h_prev_ = 0.0;
  t_prev_ = m.t;
  filters_running_ = true;
  estimate_.t = m.t;
  estimate_.eps.setZero();
  estimate_.af.setZero();
  estimate_.af_hat.setZero();
}

UpdateOutcome Estimator::update(const Measurement& m) noexcept {
  if (!(std::isfinite(m.t) && std::isfinite(m.x) && std::isfinite(m.xdot) &&
        std::isfinite(m.tbar) && std::isfinite(m.voltage))) {
    ++estimate_.skipped_nonfinite;
    return UpdateOutcome::skipped_nonfinite;
  }
  const EstimatorConfig& c = config_;
  if (std::abs(m.x) > c.x_abs_max || std::abs(m.xdot) > c.xdot_abs_max || m.tbar < c.tbar_min ||
      m.tbar > c.tbar_max || std::abs(m.voltage) > c.voltage_max) {
    ++estimate_.skipped_range;
    return UpdateOutcome::skipped_range;
  }
  if (!filters_running_) {
    start_filters(m);
    return UpdateOutcome::initialized;
  }
  const double h = m.t - t_prev_;
  if (!(h > 0.0) || !std::isfinite(h)) {
    ++estimate_.skipped_time;
    return UpdateOutcome::skipped_time;
  }
  if (h > c.max_gap_periods * c.nominal_period) {
    // The hold assumptions are meaningless over a long gap; keep what was learned (θ̂, R).
    start_filters(m);
    ++estimate_.filter_restarts;
    return UpdateOutcome::filters_restarted;
  }
  if (h != h_cached_) {
    hold_ = HoldCoefficients::make(c.beta, h);
    forget_thermal_ = ForgettingStep::make(c.forgetting, h);
    // h changes in its last bits with every sample (t is a float time), so this runs each update;
    // one expm1 less when both blocks forget at the same rate (the same bits either way).
    forget_mech_ = mech_forgetting(c) == c.forgetting ? forget_thermal_
                                                      : ForgettingStep::make(mech_forgetting(c), h);
    h_cached_ = h;
  }

  // eq. (15), column by column, and eq. (14): p is β/(s+β) applied to −βv. Smooth inputs get
  // the quadratic correction (hold_filter.hpp); x, ẋ and T̄ẋ are smoothed by the mechanical
  // dynamics. Under a held voltage T̄ is not smooth: T̄' jumps at each switch, at the sample or
  // inside the interval where a link's write landed, and a 3-point quadratic reads that kink as
  // curvature. T̄ then takes the exact path of a lag driven by the held V² (held_lag.hpp) with the
  // current θ̂5: at 100 Hz with the voltage landing mid-interval it leaves the thermal θ̂ within
  // 1e-10 (tests/estimator/test_link_timing.cpp), where the quadratic lag it replaced did not
  // (docs/numerics.md, "Filters"). V² itself is exact under ZOH,
  // split where the voltage changed.
  const Vector6 u = filter_inputs(m);
  Vector2 v;
  v << m.xdot, m.tbar;
  const bool quad = h_prev_ > 0.0;
  const auto smooth = [&](double y, double u0, double u1, double u2) noexcept {
    return quad ? hold_.quadratic(y, u0, u1, u2, h_prev_) : hold_.foh(y, u1, u2);
  };
  const double b = c.beta;
  for (int i = 0; i < 3; ++i) wf_(i) = smooth(wf_(i), u_prev2_(i), u_prev_(i), u(i));
  p_(0) = smooth(p_(0), -b * v_prev2_(0), -b * v_prev_(0), -b * v(0));
  if (c.voltage_hold == VoltageHold::zoh) {
    const bool switched_inside = m.voltage_since > t_prev_ && m.voltage_since < m.t;
    const double switch_offset = switched_inside ? m.voltage_since - t_prev_ : 0.0;
    const double a_th = std::max(0.0, estimate_.theta_hat(4));
    const HeldLagWeights lag =
        HeldLagWeights::make(hold_, b, a_th, u_prev_(5), u(5), switch_offset);
    for (int i = 3; i < 5; ++i) wf_(i) = lag.step(wf_(i), hold_.phi, u_prev_(i), u(i));
    p_(1) = lag.step(p_(1), hold_.phi, -b * v_prev_(1), -b * v(1));
    wf_(5) = switched_inside
                 ? hold_.zoh_split_step(wf_(5), u_prev_(5), u(5), b, m.t - m.voltage_since)
                 : hold_.zoh_step(wf_(5), u(5));
  } else {
    for (int i = 3; i < 6; ++i) wf_(i) = smooth(wf_(i), u_prev2_(i), u_prev_(i), u(i));
    p_(1) = smooth(p_(1), -b * v_prev2_(1), -b * v_prev_(1), -b * v(1));
  }
  u_prev2_ = u_prev_;
  v_prev2_ = v_prev_;
  u_prev_ = u;
  v_prev_ = v;
  h_prev_ = h;
  t_prev_ = m.t;

  const Vector2 af = p_ + c.beta * v;  // eq. (10)
  const Eigen::Matrix<double, 1, 4> w_mech = wf_.head<4>().transpose();
  const Eigen::Matrix<double, 1, 2> w_thermal = wf_.tail<2>().transpose();
  Vector2 af_hat;  // eq. (18), with θ̂ before this update
  af_hat << mech_.predict(w_mech), thermal_.predict(w_thermal);
  const Vector2 eps = af - af_hat;  // eq. (20)

  mech_.step(w_mech, eps(0), forget_mech_);
  thermal_.step(w_thermal, eps(1), forget_thermal_);

  estimate_.t = m.t;
  estimate_.af = af;
  estimate_.af_hat = af_hat;
  estimate_.eps = eps;
  ++estimate_.updates;
  refresh_estimate();
  return UpdateOutcome::applied;
}

void Estimator::refresh_estimate() noexcept {
  Estimate& e = estimate_;
  e.theta_hat << mech_.theta(), thermal_.theta();
  e.sigma << mech_.sigma(), thermal_.sigma();
  e.excitation << mech_.excitation(), thermal_.excitation();
  e.p_max_eig_mech = mech_.p_max_eig();
  e.p_max_eig_thermal = thermal_.p_max_eig();
  // Guard: right after reset ε and σ are ~0 before anything was learned; require at least one
  // forgetting time constant of data, (1 − e^{−1})/λP of window.
  const auto converged = [&](int first, int n, double window) {
    const double forgetting = first == 0 ? mech_forgetting(config_) : config_.forgetting;
    if (window < (1.0 - std::exp(-1.0)) / forgetting) return false;
    for (int i = first; i < first + n; ++i) {
      if (config_.known[static_cast<std::size_t>(i)]) continue;  // σ = 0, and θ0 may be 0
      if (!(e.sigma(i) < config_.converged_rel_sigma * std::abs(e.theta_hat(i)))) return false;
    }
    return true;
  };
  e.converged_mech = converged(0, 4, mech_.window());
  e.converged_thermal = converged(4, 2, thermal_.window());
}

Regressor Estimator::filtered_regressor() const noexcept {
  Regressor w = Regressor::Zero();
  w.block<1, 4>(0, 0) = wf_.head<4>().transpose();
  w.block<1, 2>(1, 4) = wf_.tail<2>().transpose();
  return w;
}

State Estimator::state() const noexcept {
  State s;
  s.theta_hat = estimate_.theta_hat;
  s.info_mech = mech_.info_theta();
  s.info_thermal = thermal_.info_theta();
  s.eps2_mean << mech_.eps2_mean(), thermal_.eps2_mean();
  s.t = estimate_.t;
  return s;
}

bool Estimator::restore(const State& s) noexcept {
  if (!s.theta_hat.allFinite() || !s.eps2_mean.allFinite() || !std::isfinite(s.t) ||
      (s.eps2_mean.array() < 0.0).any() || !symmetric_positive_definite(s.info_mech) ||
      !symmetric_positive_definite(s.info_thermal)) {
    return false;
  }
  mech_.restore(s.theta_hat.head<4>(), s.info_mech, s.eps2_mean(0));
  thermal_.restore(s.theta_hat.tail<2>(), s.info_thermal, s.eps2_mean(1));
  filters_running_ = false;
  h_cached_ = -1.0;
  estimate_.t = s.t;
  estimate_.eps.setZero();
  estimate_.af.setZero();
  estimate_.af_hat.setZero();
  refresh_estimate();
  return true;
}

}  // namespace scp::estimator

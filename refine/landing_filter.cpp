#include "refine/landing_filter.hpp"

#include <cmath>

#include "refine/matrix_functions.hpp"

namespace scp::refine {

namespace {

// The linearized transition of [x, ẋ, T̄]'s error over h, at `at`:
//   d[x, ẋ]/dt = M·[x, ẋ] + c·T̄,  dT̄/dt = −θ5·T̄,
//   M = [[0, 1], [−θ3, −(θ1 + θ2·T̄)]],  c = [0, −(θ2·ẋ + θ4)].
// Over h: [x, ẋ] ← e^{Mh}·[x, ẋ] + (∫₀ʰ e^{M(h−σ)} e^{−θ5σ} dσ)·c·T̄, and with N = (M + θ5 I)h
// that integral is e^{−θ5h}·h·φ1(N), e^{Mh} = e^{−θ5h}·e^N: one 2×2 exp_phi.
Eigen::Matrix3d transition(const Vector6& theta, const ModelState& at, double h) noexcept {
  const double th1 = theta[kDamping], th2 = theta[kDampingSlope], th3 = theta[kStiffness],
               th4 = theta[kThermalForce], th5 = theta[kCooling];
  Matrix2 n;
  n << th5, 1.0, -th3, th5 - (th1 + th2 * at.tbar);
  const ExpPhi ef = exp_phi(n * h);
  const double decay = std::exp(-th5 * h);
  Eigen::Matrix3d phi = Eigen::Matrix3d::Zero();
  phi.topLeftCorner<2, 2>() = decay * ef.exp;
  phi.block<2, 1>(0, 2) = decay * h * ef.phi1 * Eigen::Vector2d(0.0, -(th2 * at.xdot + th4));
  phi(2, 2) = decay;
  return phi;
}

}  // namespace

void LandingFilter::predict(const Vector6& theta, const ModelState& at_start,
                            const ModelState& at_end, double h, double since_landing,
                            double landing_step, double timing_variance) noexcept {
  // Linearized at the interval's mean state: at its start instead, the mechanical part of P is
  // off where ẋ turns within an interval (an underdamped actuator; docs/numerics.md, "Figures
  // behind the code comments").
  const ModelState mid{0.5 * (at_start.x + at_end.x), 0.5 * (at_start.xdot + at_end.xdot),
                       0.5 * (at_start.tbar + at_end.tbar)};
  if (!zero_ && h > 0.0) {
    const Eigen::Matrix3d phi = transition(theta, mid, h);
    p_ = phi * p_ * phi.transpose();
    p_ = 0.5 * (p_ + p_.transpose()).eval();
  }
  if (since_landing > 0.0 && landing_step != 0.0 && timing_variance > 0.0) {
    // A landing δ late leaves T̄ short by θ6·ΔV²·δ at the switch; carried to the interval's end.
    const Eigen::Vector3d effect = landing_step * transition(theta, mid, since_landing).col(2);
    p_ += timing_variance * effect * effect.transpose();
    zero_ = false;
  }
}

Eigen::Matrix2d LandingFilter::output_covariance() const noexcept {
  Eigen::Matrix2d out;
  out << p_(0, 0), p_(0, 2), p_(2, 0), p_(2, 2);
  return out;
}

Eigen::Vector3d LandingFilter::update_with_tbar(double measurement_variance,
                                                double omega) noexcept {
  if (zero_) return Eigen::Vector3d::Zero();
  const double innovation_variance = p_(2, 2) + measurement_variance;
  if (!(innovation_variance > 0.0)) return Eigen::Vector3d::Zero();
  const Eigen::Vector3d gain = (omega / innovation_variance) * p_.col(2);
  // P − ω·P e₃ e₃ᵀ P/S: symmetric, and positive semi-definite for ω ≤ 1.
  p_ -= gain * p_.row(2);
  p_ = 0.5 * (p_ + p_.transpose()).eval();
  return gain;
}

}  // namespace scp::refine

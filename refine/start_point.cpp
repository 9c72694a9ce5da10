// The window's check and the fit's start (refine/stages.hpp).
#include <Eigen/Cholesky>
#include <cmath>

#include "refine/stages.hpp"

namespace scp::refine {

namespace {

// θ5, θ6 from dT̄/dt ≈ −θ5·T̄ + θ6·V² by least squares on sample differences: biased by noise on
// T̄ only as much as the noise is against T̄'s range, plenty for a start.
Eigen::Vector2d thermal_from_data(std::span<const WindowSample> w) {
  Eigen::Matrix2d a = Eigen::Matrix2d::Zero();
  Eigen::Vector2d b = Eigen::Vector2d::Zero();
  for (std::size_t k = 1; k < w.size(); ++k) {
    const double dt = w[k].t - w[k - 1].t;
    const Eigen::Vector2d row(-0.5 * (w[k].tbar + w[k - 1].tbar), w[k].voltage * w[k].voltage);
    const double y = (w[k].tbar - w[k - 1].tbar) / dt;
    // Weighted by dt² so that the sum is over equation-error per interval, not per second⁻¹.
    a.noalias() += dt * dt * row * row.transpose();
    b.noalias() += dt * dt * row * y;
  }
  const Eigen::Vector2d th = a.ldlt().solve(b);
  return {th.allFinite() && th[0] > 0.0 ? th[0] : 0.05,
          th.allFinite() && th[1] > 0.0 ? th[1] : 1.0};
}

// A mechanical shape with poles at −1 and −1000 rad/s at scale 1, no temperature-dependent
// damping, and the static gain x ≈ −(θ4/θ3)·T̄ fitted to the data; the scale search places it.
Eigen::Vector4d default_mechanical_shape(std::span<const WindowSample> w) {
  double xt = 0.0, tt = 0.0;
  for (const WindowSample& s : w) {
    xt += s.x * s.tbar;
    tt += s.tbar * s.tbar;
  }
  const double gain = tt > 0.0 ? -xt / tt : 0.0;
  return {1001.0, 0.0, 1000.0, gain * 1000.0};
}

}  // namespace

StopReason check_window(std::span<const WindowSample> w) {
  if (w.size() < 3) return StopReason::window_too_short;
  for (std::size_t k = 0; k < w.size(); ++k) {
    const WindowSample& s = w[k];
    if (!std::isfinite(s.t) || !std::isfinite(s.x) || !std::isfinite(s.tbar) ||
        !std::isfinite(s.voltage) || std::isnan(s.voltage_since))
      return StopReason::window_not_finite;
    if (k > 0 && !(s.t > w[k - 1].t)) return StopReason::window_times_not_increasing;
  }
  return StopReason::none;
}

ParamVector start_point(std::span<const WindowSample> window, const Vector6& theta_start,
                        const std::array<bool, kThetaSize>& known) {
  ParamVector p =
      param_vector(theta_start, Eigen::Vector3d(window.front().x, 0.0, window.front().tbar));
  const bool thermal_usable = std::isfinite(p[kCooling]) && std::isfinite(p[kHeating]) &&
                              p[kCooling] > 0.0 && p[kHeating] > 0.0;
  if (!thermal_usable) {
    const Eigen::Vector2d from_data = thermal_from_data(window);
    for (std::size_t j = 0; j < kThermalTheta.size(); ++j)
      if (!known[kThermalTheta[j]]) p[kThermalTheta[j]] = from_data[static_cast<Eigen::Index>(j)];
  }
  const bool mechanical_usable =
      p.head<kMechanicalSize>().allFinite() && p[kDamping] > 0.0 && p[kStiffness] > 0.0;
  if (!mechanical_usable) {
    const Eigen::Vector4d shape = default_mechanical_shape(window);
    for (int j = 0; j < kMechanicalSize; ++j)
      if (!known[j]) p[j] = shape[j];
  }
  return p;
}

}  // namespace scp::refine

// The window's check and the fit's start (refine/stages.hpp).
#include <Eigen/Cholesky>
#include <cmath>
#include <limits>

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

// x ≈ zero − gain·(T̄ − offset − drift·(t − t0)) by least squares over the window (the T̄
// nuisance terms from p; 0 before the thermal stage). NaN where T̄ does not vary.
struct StaticLine {
  double zero = 0.0, gain = 0.0;
};
StaticLine static_line(std::span<const WindowSample> w, const ParamVector& p) {
  const auto model_tbar = [&](const WindowSample& s) {
    return s.tbar - p[kAmbientOffsetSlot] - p[kAmbientDriftSlot] * (s.t - w.front().t);
  };
  double mean_x = 0.0, mean_t = 0.0;
  for (const WindowSample& s : w) {
    mean_x += s.x;
    mean_t += model_tbar(s);
  }
  mean_x /= static_cast<double>(w.size());
  mean_t /= static_cast<double>(w.size());
  double xt = 0.0, tt = 0.0;
  for (const WindowSample& s : w) {
    xt += (s.x - mean_x) * (model_tbar(s) - mean_t);
    tt += (model_tbar(s) - mean_t) * (model_tbar(s) - mean_t);
  }
  const double gain = tt > 0.0 ? -xt / tt : std::numeric_limits<double>::quiet_NaN();
  return {mean_x + gain * mean_t, gain};
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
  if (!usable_mechanical_start(theta_start))
    start_mechanical_shape(window, kDefaultShape, known, p);
  return p;
}

// The shape's θ1 and θ3 with no temperature-dependent damping, and the static gain of the
// window's static line (with its constant: through the origin, a displacement zero of a fifth of
// the stroke bent the gain so far that the fit ended at a fast pole); the scale search places it.
void start_mechanical_shape(std::span<const WindowSample> window, const MechanicalShape& shape,
                            const std::array<bool, kThetaSize>& known, ParamVector& p) {
  const double gain = static_line(window, ParamVector::Zero()).gain;
  const Eigen::Vector4d theta(shape.damping, 0.0, shape.stiffness,
                              std::isfinite(gain) ? gain * shape.stiffness : 0.0);
  for (int j = 0; j < kMechanicalSize; ++j)
    if (!known[j]) p[j] = theta[j];
}

bool usable_mechanical_start(const Vector6& theta) {
  return theta.head<kMechanicalSize>().allFinite() && theta[kDamping] > 0.0 &&
         theta[kStiffness] > 0.0;
}

void start_displacement_zero(std::span<const WindowSample> window, const FitSettings& settings,
                             ParamVector& p) {
  if (settings.nuisance.x_zero.fixed) return;
  const StaticLine line = static_line(window, p);
  if (!std::isfinite(line.zero)) return;
  p[kXZeroSlot] = line.zero;
  p[kX0] = window.front().x - line.zero;
}

}  // namespace scp::refine

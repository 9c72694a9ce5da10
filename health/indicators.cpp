#include "health/indicators.hpp"

#include <algorithm>
#include <cmath>

namespace scp::health {

namespace {

IndicatorValue with_delta_method(double value, const Vector6& gradient, const Matrix6& c) {
  IndicatorValue out;
  const double variance = gradient.dot(c * gradient);
  out.known = std::isfinite(value) && std::isfinite(variance);
  out.value = value;
  out.sigma = std::sqrt(std::max(0.0, variance));
  return out;
}

// a/b with its gradient in θ_a and θ_b.
IndicatorValue ratio(const Vector6& t, const Matrix6& c, int a, int b) {
  if (t[b] == 0.0) return {};
  Vector6 g = Vector6::Zero();
  g[a] = 1.0 / t[b];
  g[b] = -t[a] / (t[b] * t[b]);
  return with_delta_method(t[a] / t[b], g, c);
}

// scale/θ_i.
IndicatorValue reciprocal(const Vector6& t, const Matrix6& c, int i, double scale) {
  if (t[i] == 0.0) return {};
  Vector6 g = Vector6::Zero();
  g[i] = -scale / (t[i] * t[i]);
  return with_delta_method(scale / t[i], g, c);
}

}  // namespace

Indicators derive_indicators(const Vector6& theta, const Matrix6& covariance,
                             double heat_capacity_j_per_c) noexcept {
  Indicators out{};
  auto at = [&out](Indicator i) -> IndicatorValue& { return out[static_cast<int>(i)]; };
  at(Indicator::thermal_time_constant) = reciprocal(theta, covariance, 4, 1.0);
  at(Indicator::static_gain) = ratio(theta, covariance, 3, 2);
  at(Indicator::mechanical_time_constant) = ratio(theta, covariance, 0, 2);
  Vector6 g = Vector6::Zero();
  g[2] = 1.0;
  at(Indicator::stiffness_per_mass) = with_delta_method(theta[2], g, covariance);
  at(Indicator::heating_per_power) = ratio(theta, covariance, 5, 4);
  if (heat_capacity_j_per_c > 0.0) {
    at(Indicator::resistance) = reciprocal(theta, covariance, 5, 1.0 / heat_capacity_j_per_c);
    g.setZero();
    g[4] = heat_capacity_j_per_c;
    at(Indicator::cooling) = with_delta_method(theta[4] * heat_capacity_j_per_c, g, covariance);
  }
  return out;
}

}  // namespace scp::health

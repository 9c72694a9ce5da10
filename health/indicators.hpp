#pragma once
// Physical condition indicators derived from θ = [b/m, α1/m, k/m, α2/m, λ/Cth, 1/(R·Cth)], each
// with σ by the delta method (σ² = gᵀ C g, g the gradient at θ̂). Only what θ determines: the mass,
// Cth, λ and R are not separately identifiable, except R and λ when Cth is known.

#include <array>

#include "health/types.hpp"

namespace scp::health {

enum class Indicator : int {
  thermal_time_constant,     // Cth/λ = 1/θ5, s
  static_gain,               // α2/k = θ4/θ3, m/°C: displacement per degree at rest
  mechanical_time_constant,  // b/k = θ1/θ3, s: the slow mechanical pole when it is overdamped
  stiffness_per_mass,        // k/m = θ3, 1/s²
  heating_per_power,         // 1/(R·λ) = θ6/θ5, °C/V²: the steady temperature rise per V²
  resistance,                // R = 1/(θ6·Cth), Ω: only with a known Cth
  cooling,                   // λ = θ5·Cth, W/°C: only with a known Cth
};
inline constexpr int kIndicators = 7;
inline constexpr std::array<const char*, kIndicators> kIndicatorNames = {
    "thermal_time_constant_s", "static_gain_m_per_c",        "mechanical_time_constant_s",
    "stiffness_per_mass_s2",   "heating_per_power_c_per_v2", "resistance_ohm",
    "cooling_w_per_c"};

struct IndicatorValue {
  bool known = false;  // computable from this θ (a known Cth for R and λ; nonzero divisors)
  double value = 0.0;
  double sigma = 0.0;
};
using Indicators = std::array<IndicatorValue, kIndicators>;

// heat_capacity_j_per_c ≤ 0: Cth unknown, R and λ left out.
Indicators derive_indicators(const Vector6& theta, const Matrix6& covariance,
                             double heat_capacity_j_per_c = 0.0) noexcept;

}  // namespace scp::health

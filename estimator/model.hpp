#pragma once
// The SCP actuator model of the paper and the map between its physical parameters and the
// linearly-parametrised vector θ of eq. (7):
//   m ẍ + b ẋ + α1 T̄ ẋ + k x = −α2 T̄          (mechanical, eq. (1))
//   Cth dT̄/dt = −λ T̄ + V²/R                    (thermal, eq. (2)), T̄ = T − Tamb.
// θ = [b/m, α1/m, k/m, α2/m, λ/Cth, 1/(R·Cth)].
//
// The numeric θ printed in Section IV of the paper ([1.247e3, 8e-4, 1.813, ...]) does not follow
// from Table I; the values here are derived from Table I: [1247, 0.8, 1813, 0.1, 0.0594059,
// 1.1001100] (see PAPER-NOTES).

#include "estimator/types.hpp"

namespace scp::estimator {

// SI units: kg, Ω, Ws/°C, W/°C, Ns/m, N/m, Ns/°C, N/°C.
struct PhysicalParams {
  double m, R, Cth, lambda, b, k, alpha1, alpha2;
};

// Table I of the paper: m=0.1, R=1, Cth=0.9090, λ=0.0540, b=124.7, k=181.3, α1=0.08, α2=0.01.
PhysicalParams table1_params() noexcept;

// eq. (7).
Vector6 theta_from_physical(const PhysicalParams& p) noexcept;

// Inverse of eq. (7). θ fixes only ratios, so the mass m and the resistance R must be known
// (measured separately); Cth then follows from θ6 = 1/(R·Cth). A zero θ6 gives non-finite Cth and
// λ: callers check std::isfinite before showing them.
PhysicalParams physical_from_theta(const Vector6& theta, double m, double R) noexcept;

}  // namespace scp::estimator

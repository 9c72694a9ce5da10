#pragma once
// Physical parameters of the simulated SCP actuator (Table I of the paper) and their drift.

#include <array>

namespace scp::drivers::sim {

// Table I. Units: m [kg], R [Ω], Cth [Ws/°C], lambda [W/°C], b [Ns/m], k [N/m],
// alpha1 [Ns/(m·°C)], alpha2 [N/°C].
struct PlantParams {
  double m = 0.1, R = 1.0, Cth = 0.9090, lambda = 0.0540, b = 124.7, k = 181.3, alpha1 = 0.08,
         alpha2 = 0.01;
};

// Relative drift rate per hour of each physical parameter: p(t) = p0·(1 + rate·t/3600).
struct PlantDrift {
  double m = 0, R = 0, Cth = 0, lambda = 0, b = 0, k = 0, alpha1 = 0, alpha2 = 0;
};

// Smallest factor a drifting parameter may shrink to: a large negative rate must not make a mass,
// a resistance or a thermal mass zero or negative (the model would stop being physical).
inline constexpr double kMinDriftFactor = 1e-3;

// The parameters of `p0` drifted to time t (s) at `rate`.
PlantParams drifted(const PlantParams& p0, const PlantDrift& rate, double t) noexcept;

bool has_drift(const PlantDrift& rate) noexcept;

// θ = [b/m, α1/m, k/m, α2/m, λ/Cth, 1/(R·Cth)], eq. (7). Derived from Table I this is
// [1247, 0.8, 1813, 0.1, 0.0594059, 1.1001100]; the vector printed in Section IV is misscaled.
std::array<double, 6> theta_of(const PlantParams& p) noexcept;

}  // namespace scp::drivers::sim

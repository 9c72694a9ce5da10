#pragma once
// Physical parameters of the simulated SCP actuator (Table I of the paper), their drift, and the
// ways a real bench departs from the paper's model.

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

// How a real bench departs from eqs. (1)-(2) (issue 28; VALIDATION-NOTES §3). Each is 0 (off) by
// default; with all of them off the plant is the paper's model, integrated as before.
struct PlantDeviations {
  // Temperature coefficients in 1/°C, of T̄ measured from the TRUE ambient. The parameters of
  // PlantParams are their values at T̄ = 0, so θ keeps the paper's meaning there.
  double resistance_tempco = 0;    // ρ: R(T̄) = R0·(1 + ρ·T̄); a nickel heater ≈ 0.0059
  double stiffness_softening = 0;  // κ: k(T̄) = k0·(1 − κ·T̄); nylon softens when heated
  double cooling_tempco = 0;       // γ: λ(T̄) = λ0·(1 + γ·T̄); free convection grows with T
  // The true ambient is the configured one + offset + drift·t/3600 (t the plant's time). T̄ is
  // measured from it, so a drifting room adds −drift/3600 to dT̄/dt, and the actuator rests at
  // x = 0 at the true ambient.
  double ambient_offset_c = 0;       // °C
  double ambient_drift_c_per_h = 0;  // °C per hour
  // First-order lag of the temperature sensor, s (0 = none): τ·dTs/dt = T − Ts. A property of the
  // sensor, integrated with the plant's states so that it sees T̄ inside each step.
  double temperature_lag_s = 0;
};

// Smallest value the factors (1 + ρT̄), (1 − κT̄), (1 + γT̄) may take: a coefficient large enough
// to drive R, k or λ through zero would stop the model being physical (and k < 0 unstable).
inline constexpr double kMinTempcoFactor = 1e-3;

// Whether any deviation changes the dynamics (all but the ambient offset, which only shifts what
// the temperature sensor reads): the plant then integrates all its states together.
bool changes_dynamics(const PlantDeviations& d) noexcept;

// The parameters of `p0` drifted to time t (s) at `rate`.
PlantParams drifted(const PlantParams& p0, const PlantDrift& rate, double t) noexcept;

bool has_drift(const PlantDrift& rate) noexcept;

// θ = [b/m, α1/m, k/m, α2/m, λ/Cth, 1/(R·Cth)], eq. (7). Derived from Table I this is
// [1247, 0.8, 1813, 0.1, 0.0594059, 1.1001100]; the vector printed in Section IV is misscaled.
std::array<double, 6> theta_of(const PlantParams& p) noexcept;

}  // namespace scp::drivers::sim

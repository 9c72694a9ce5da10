#pragma once
// The SCP actuator itself: eqs. (1)–(2) integrated with the voltage held over each step.
//
//   m ẍ + b ẋ + α1 T̄ ẋ + k x = −α2 T̄        (1)
//   Cth dT̄/dt = −λ T̄ + V²/R                  (2)
//
// The thermal equation is linear with a constant input over a step, so it is solved exactly.
// The mechanical one is stiff (poles near −1.455 and −1245.5 rad/s) and is integrated with
// classical RK4 sub-steps that see the exact T̄(τ) inside the step.

#include "drivers/sim/plant_params.hpp"

namespace scp::drivers::sim {

class Plant {
 public:
  // `substeps_per_ms`: RK4 sub-steps per millisecond of simulated time (at least one per step).
  // 20 keeps h·|fast pole| ≈ 0.06, far inside RK4's stability region (≈ 2.78) and accurate to
  // ~1e-9 relative; a longer step gets proportionally more sub-steps, so it never goes unstable.
  explicit Plant(const PlantParams& params = {}, int substeps_per_ms = 20,
                 const PlantDrift& drift = {}) noexcept;

  // Advances by dt seconds with `voltage` held (a DAC holds its output). dt ≤ 0 or a non-finite
  // argument leaves the state unchanged.
  void step(double voltage, double dt) noexcept;

  double x() const noexcept { return x_; }
  double xdot() const noexcept { return xdot_; }
  double tbar() const noexcept { return tbar_; }
  double time() const noexcept { return t_; }  // s of simulated time since construction
  void set_state(double x, double xdot, double tbar) noexcept;
  void set_time(double t) noexcept { t_ = t; }

  // The parameters in effect now (drifted when a drift rate is set).
  const PlantParams& params() const noexcept { return params_; }
  // Replaces the nominal parameters p0 (drift, if any, then applies to them).
  void set_params(const PlantParams& params) noexcept;
  const PlantParams& nominal_params() const noexcept { return p0_; }
  const PlantDrift& drift() const noexcept { return drift_; }

 private:
  PlantParams p0_;
  PlantParams params_;
  PlantDrift drift_;
  bool drifting_ = false;
  int substeps_per_ms_;
  double x_ = 0.0, xdot_ = 0.0, tbar_ = 0.0, t_ = 0.0;
};

}  // namespace scp::drivers::sim

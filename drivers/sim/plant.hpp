#pragma once
// The SCP actuator itself: eqs. (1)–(2), optionally with a real bench's deviations from them.
//
//   m ẍ + b ẋ + α1 T̄ ẋ + k x = −α2 T̄        (1)
//   Cth dT̄/dt = −λ T̄ + V²/R                  (2)
//
// With the paper's model and the voltage held over a step (a DAC), the thermal equation is linear
// with a constant input, so it is solved exactly; the mechanical one is stiff (poles near −1.455
// and −1245.5 rad/s) and is integrated with classical RK4 sub-steps that see the exact T̄(τ).
// With a deviation that changes the dynamics (PlantDeviations: R, k or λ depending on T̄, a
// drifting ambient, a lagging temperature sensor), or a voltage that varies inside the step, all
// states [x, ẋ, T̄, Ts] are integrated together by RK4 at the same sub-step.

#include <concepts>
#include <type_traits>

#include "drivers/sim/plant_params.hpp"

namespace scp::drivers::sim {

// A voltage as a function of the plant's time, V(t): a non-owning reference to a callable
// double(double), so that a continuous excitation reaches the integrator without an allocation.
// The callable must outlive the call it is passed to.
class VoltageOfTime {
 public:
  template <class F>
  requires(
      !std::same_as<std::remove_cvref_t<F>, VoltageOfTime> &&
      std::is_invocable_r_v<double, const F&, double>) explicit VoltageOfTime(const F& f) noexcept
      : object_(&f),
        call_([](const void* object, double t) { return (*static_cast<const F*>(object))(t); }) {}

  double operator()(double t) const noexcept { return call_(object_, t); }

 private:
  const void* object_;
  double (*call_)(const void*, double);
};

class Plant {
 public:
  // `substeps_per_ms`: RK4 sub-steps per millisecond of simulated time (at least one per step).
  // 20 keeps h·|fast pole| ≈ 0.06, far inside RK4's stability region (≈ 2.78) and accurate to
  // ~1e-9 relative; a longer step gets proportionally more sub-steps, so it never goes unstable.
  explicit Plant(const PlantParams& params = {}, int substeps_per_ms = 20,
                 const PlantDrift& drift = {}, const PlantDeviations& deviations = {}) noexcept;

  // Advances by dt seconds with `voltage` held (a DAC holds its output). dt ≤ 0 or a non-finite
  // argument leaves the state unchanged.
  void step(double voltage, double dt) noexcept;
  // Advances by dt seconds with the voltage V(t), t the plant's time in [time(), time() + dt]:
  // a continuous excitation, or a ramp between two commands. All states by RK4, V evaluated at
  // each sub-step's ends and middle; a discontinuity of V belongs at the end of a step (cut the
  // step there, and let the callable give the value before it up to that end).
  void step(VoltageOfTime voltage, double dt) noexcept;

  double x() const noexcept { return x_; }
  double xdot() const noexcept { return xdot_; }
  double tbar() const noexcept { return tbar_; }  // from the TRUE ambient
  double time() const noexcept { return t_; }     // s of simulated time since construction
  // Sets the state; the temperature sensor starts at its equilibrium with it (no lag pending).
  void set_state(double x, double xdot, double tbar) noexcept;
  void set_time(double t) noexcept { t_ = t; }

  // What the temperature sensor reads now, less the configured ambient: T̄ plus the true
  // ambient's offset and drift from the configured one, through the sensor's lag if any.
  double sensed_tbar() const noexcept;
  // Sets the lagging sensor's state (sensed_tbar()); no effect without a lag.
  void set_sensed_tbar(double sensed) noexcept { sensed_ = sensed; }
  // The true ambient less the configured one at time() (°C).
  double ambient_shift() const noexcept;
  // The heater's resistance now, R(T̄) = R·(1 + ρT̄), and its current at `voltage`.
  double resistance() const noexcept;
  double current(double voltage) const noexcept { return voltage / resistance(); }

  // The parameters in effect now (drifted when a drift rate is set), at T̄ = 0.
  const PlantParams& params() const noexcept { return params_; }
  // Replaces the nominal parameters p0 (drift, if any, then applies to them).
  void set_params(const PlantParams& params) noexcept;
  const PlantParams& nominal_params() const noexcept { return p0_; }
  const PlantDrift& drift() const noexcept { return drift_; }
  const PlantDeviations& deviations() const noexcept { return deviations_; }

 private:
  void update_drifted_params(double dt) noexcept;
  long substeps_for(double dt) const noexcept;
  // eq. (2) exact and eq. (1) by RK4, for the paper's model with V held.
  void step_paper_model(double voltage, double dt) noexcept;
  // All states together by RK4.
  void step_joint(VoltageOfTime voltage, double dt) noexcept;

  PlantParams p0_;
  PlantParams params_;
  PlantDrift drift_;
  PlantDeviations deviations_;
  bool drifting_ = false;
  bool joint_ = false;  // a deviation changes the dynamics: always step_joint
  int substeps_per_ms_;
  double x_ = 0.0, xdot_ = 0.0, tbar_ = 0.0, t_ = 0.0;
  double sensed_ = 0.0;  // the lagging temperature sensor's state, as sensed_tbar()
};

}  // namespace scp::drivers::sim

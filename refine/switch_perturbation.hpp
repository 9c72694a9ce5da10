#pragma once
// The linear model of a voltage switch's perturbation along a fitted trajectory, sample by sample:
// what refine/switch_placement.cpp places the switches with and refine/switch_columns.cpp
// carries to the validator's blocks. Internal to those files.

#include <Eigen/Core>
#include <cmath>
#include <cstddef>
#include <limits>
#include <span>
#include <vector>

#include "refine/fit.hpp"
#include "refine/matrix_functions.hpp"
#include "refine/model_simulator.hpp"

namespace scp::refine::switch_model {

// A switch's perturbation of the model: T̄'s D, its reading y, and x's δx, δẋ.
using Perturbation = Eigen::Vector4d;
using PerturbationMap = Eigen::Matrix4d;
using OutputRow = Eigen::RowVector4d;
constexpr int kD = 0, kReading = 1, kX = 2;

// A switch row and what moving its switch does to the model.
struct Switch {
  std::size_t row = 0;
  double phase = 0.0;  // where it is now: 0 at the previous sample, 1 at the row
  // The perturbation at the row per unit of phase later: (D, y) = heat·(1, 1 − lag), heat =
  // θ6·(A² − B²)·Δ at the local heating; x has not moved yet.
  Perturbation start = Perturbation::Zero();
};

// The rows a foh window holds (hold_voltage_switches' switches), at their phases; start unset.
std::vector<Switch> switch_rows(std::span<const WindowSample> w);

// e^x of the last x asked for: the sweep's decays repeat from sample to sample (a uniform Δ, and
// without an extension the same θ5), where a call per sample would cost as much as the sums.
class RepeatedExp {
 public:
  double operator()(double x) noexcept {
    if (x != x_) {
      x_ = x;
      value_ = std::exp(x);
    }
    return value_;
  }

 private:
  double x_ = std::numeric_limits<double>::quiet_NaN();  // never equal: the first call computes
  double value_ = 0.0;
};

// The mechanical block's exact step over Δ, linearised about the trajectory: e^{MΔ} and Δ·φ1(MΔ)
// of M = [0 1; −k −c] (c the damping, k the stiffness at T̄), recomputed where c or k moved by
// more than kMechanicalTolerance of itself or Δ changed (a uniform record's Δ differs in its last
// bits from sample to sample).
class MechanicalSteps {
 public:
  MechanicalSteps(const Vector6& theta, const Tempcos& tc) : theta_(theta), tc_(tc) {}
  const ExpPhi& at(double dt, const ModelState& s) {
    const double damping = theta_[kDamping] + theta_[kDampingSlope] * s.tbar;
    const double stiffness = theta_[kStiffness] * (1.0 - tc_.kappa * s.tbar);
    if (!near(dt, dt_) || !near(damping, damping_) || !near(stiffness, stiffness_)) {
      Matrix2 m;
      m << 0.0, 1.0, -stiffness, -damping;
      step_ = exp_phi(m * dt);
      dt_ = dt;
      damping_ = damping;
      stiffness_ = stiffness;
    }
    return step_;
  }

 private:
  static bool near(double a, double b) {
    return std::abs(a - b) <= kMechanicalTolerance * std::abs(b);
  }
  static constexpr double kMechanicalTolerance = 1e-3;
  Vector6 theta_;
  Tempcos tc_;
  double dt_ = std::numeric_limits<double>::quiet_NaN();
  double damping_ = 0.0, stiffness_ = 0.0;
  ExpPhi step_{};
};

// Whether a perturbation's x is wanted, or only T̄ and its reading.
enum class Outputs : bool { thermal, both };

// The linear model of a switch's perturbation along the fitted trajectory, sample by sample.
class PerturbationSteps {
 public:
  PerturbationSteps(const FitResult& fit, Outputs outputs);

  // Sample k's (k > 0) step of the perturbation from k − 1, the model's V² over it
  // `thermal_input`; at a switch row, the switch's start too.
  PerturbationMap step(std::span<const WindowSample> w, std::size_t k, double thermal_input,
                       Perturbation* start) {
    const double dt = w[k].t - w[k - 1].t;
    const ThermalLinearization l = linearize_thermal(theta_, tc_, prev_.tbar, thermal_input);
    const double lag = sensor_lag_ > 0.0 ? lag_decay_(-dt / sensor_lag_) : 0.0;
    if (start != nullptr) {
      const SwitchLevels levels = switch_levels(w[k - 1], w[k]);
      const double heat = l.b * (levels.before - levels.after) * dt;
      *start << heat, heat * (1.0 - lag), 0.0, 0.0;
    }
    const double decay = thermal_decay_(-l.a * dt);
    PerturbationMap a = PerturbationMap::Zero();
    a(kD, kD) = decay;
    a(kReading, kD) = (1.0 - lag) * decay;
    a(kReading, kReading) = lag;
    if (outputs_ == Outputs::thermal) return a;
    // x's force per unit of D: ∂/∂T̄ of −(θ1 + θ2T̄)ẋ − θ3(1 − κT̄)x − θ4T̄, D at its mean over
    // the interval (to first order in its decay).
    const double force = -(theta_[kThermalForce] + theta_[kDampingSlope] * prev_.xdot -
                           theta_[kStiffness] * tc_.kappa * prev_.x);
    const ExpPhi& m = mechanical_.at(dt, prev_);
    a.bottomRightCorner<2, 2>() = m.exp;
    a.bottomLeftCorner<2, 1>() = (0.5 * (1.0 + decay) * force * dt) * m.phi1.col(1);
    return a;
  }
  // After sample k's outputs: its state linearizes the next step.
  void passed(const ModelState& s) { prev_ = s; }

 private:
  Vector6 theta_;
  Tempcos tc_;
  double sensor_lag_;
  Outputs outputs_;
  ModelState prev_;
  MechanicalSteps mechanical_;
  RepeatedExp lag_decay_, thermal_decay_;
};

}  // namespace scp::refine::switch_model

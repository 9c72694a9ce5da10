#pragma once
// The parameter vector p that the fit, its sensitivities and its covariance work on, laid out
// once: the paper's θ (eq. (7)), then the model's state at the window's first sample. A term the
// fit learns to estimate (a sensor's zero, an ambient offset, an extension's coefficient) is a
// slot added here: every vector, matrix and mask of the fit is sized by kParams, and the
// channels a slot acts on are declared beside it (acts_on_tbar).

#include <Eigen/Core>
#include <array>

#include "estimator/types.hpp"
#include "refine/fit_terms.hpp"

namespace scp::refine {

// θ = [b/m, α1/m, k/m, α2/m, λ/Cth, 1/(R·Cth)]: θ1..θ6 of the paper.
inline constexpr int kDamping = 0;       // θ1 = b/m
inline constexpr int kDampingSlope = 1;  // θ2 = α1/m: the damping's change per °C of T̄
inline constexpr int kStiffness = 2;     // θ3 = k/m
inline constexpr int kThermalForce = 3;  // θ4 = α2/m: the contraction's force per °C of T̄
inline constexpr int kCooling = 4;       // θ5 = λ/Cth
inline constexpr int kHeating = 5;       // θ6 = 1/(R·Cth)
// The model's state at the window's first sample: x, ẋ, T̄.
inline constexpr int kX0 = 6, kXdot0 = 7, kTbar0 = 8;
// The slots the simulation sees (θ and the initial state); the ones after act on the outputs only.
inline constexpr int kModelSlots = 9;
// The nuisance terms of a real bench (refine/fit_terms.hpp, their signs): the displacement
// sensor's zero (m), added to x; the ambient's offset (°C) and drift (°C/s, from the window's
// first sample), added to T̄.
inline constexpr int kXZeroSlot = 9, kAmbientOffsetSlot = 10, kAmbientDriftSlot = 11;
// The model's extensions (refine/fit_terms.hpp), seen by the simulation: the heater resistance's
// temperature coefficient ρ, the stiffness's softening κ, the cooling's coefficient γ (1/°C).
// Last, so that a fit without them works on the same leading slots as before they existed.
inline constexpr int kResistanceTempcoSlot = 12, kStiffnessSofteningSlot = 13,
                     kCoolingTempcoSlot = 14;
inline constexpr int kFirstExtensionSlot = 12, kExtensionSlots = 3;
// The temperature sensor's lag τs (s, refine/sensor_lag.hpp), on T̄'s output.
inline constexpr int kSensorLagSlot = 15;
inline constexpr int kParams = 16;
// The optional slots, whose sensitivities a pass carries only for a fit that estimates one of
// them (PassSettings::extensions): the extensions and the sensor's lag, last.
inline constexpr int kFirstOptionalSlot = kFirstExtensionSlot;
static_assert(kSensorLagSlot + 1 == kParams &&
                  kFirstExtensionSlot + kExtensionSlots == kSensorLagSlot,
              "the optional slots are p's tail");

inline constexpr int kThetaSize = 6;
inline constexpr int kMechanicalSize = 4;  // θ1..θ4, at the head of θ
inline constexpr std::array<int, kMechanicalSize> kMechanicalTheta{kDamping, kDampingSlope,
                                                                   kStiffness, kThermalForce};
inline constexpr std::array<int, 2> kThermalTheta{kCooling, kHeating};

using ParamVector = Eigen::Matrix<double, kParams, 1>;
using ParamMatrix = Eigen::Matrix<double, kParams, kParams>;

// The slots a fit estimates; the others stay where they started.
using FreeMask = std::array<bool, kParams>;

// θ free unless `known`, the initial state always (a nuisance the window must pay for); the
// nuisance terms held (the paper's model).
inline FreeMask free_slots(const std::array<bool, kThetaSize>& known) {
  FreeMask free{};
  for (int i = 0; i < kThetaSize; ++i) free[i] = !known[i];
  free[kX0] = free[kXdot0] = free[kTbar0] = true;
  return free;
}

// The same with the nuisance terms free unless `nuisance` fixes them.
inline FreeMask free_slots(const std::array<bool, kThetaSize>& known,
                           const NuisanceSettings& nuisance) {
  FreeMask free = free_slots(known);
  free[kXZeroSlot] = !nuisance.x_zero.fixed;
  free[kAmbientOffsetSlot] = !nuisance.ambient_offset.fixed;
  free[kAmbientDriftSlot] = !nuisance.ambient_drift.fixed;
  free[kSensorLagSlot] = !nuisance.sensor_lag.fixed;
  return free;
}

constexpr bool is_extension(int slot) {
  return slot >= kFirstExtensionSlot && slot < kFirstExtensionSlot + kExtensionSlots;
}
constexpr bool is_optional(int slot) {
  return slot >= kFirstOptionalSlot;
}

// Whether a slot moves the model's T̄ (the thermal block does not see x); every slot of the
// simulation moves x.
constexpr bool acts_on_tbar(int slot) {
  return slot == kCooling || slot == kHeating || slot == kTbar0 || slot == kResistanceTempcoSlot ||
         slot == kCoolingTempcoSlot;
}
// Whether a slot moves the x or the T̄ the fit compares with the measurement.
constexpr bool in_x_output(int slot) {
  return slot != kAmbientOffsetSlot && slot != kAmbientDriftSlot && slot != kSensorLagSlot;
}
constexpr bool in_tbar_output(int slot) {
  return acts_on_tbar(slot) || slot == kAmbientOffsetSlot || slot == kAmbientDriftSlot ||
         slot == kSensorLagSlot;
}

// The model's outputs at a sample `since` s after the window's first, from the simulation's
// (x, T̄) and p's nuisance slots.
inline double x_output(const ParamVector& p, double x_model) {
  return x_model + p[kXZeroSlot];
}
inline double tbar_output(const ParamVector& p, double tbar_model, double since) {
  return tbar_model + p[kAmbientOffsetSlot] + p[kAmbientDriftSlot] * since;
}

// p's nuisance slots at their fixed values (the estimated ones start at 0).
inline void set_nuisance_start(const NuisanceSettings& n, ParamVector& p) {
  p[kXZeroSlot] = n.x_zero.fixed ? n.x_zero.value : 0.0;
  p[kAmbientOffsetSlot] = n.ambient_offset.fixed ? n.ambient_offset.value : 0.0;
  p[kAmbientDriftSlot] = n.ambient_drift.fixed ? n.ambient_drift.value : 0.0;
  p[kSensorLagSlot] = n.sensor_lag.fixed ? n.sensor_lag.value : 0.0;
}

// p from θ and the initial state (every other slot 0).
inline ParamVector param_vector(const estimator::Vector6& theta, const Eigen::Vector3d& initial) {
  ParamVector p = ParamVector::Zero();
  p.head<kThetaSize>() = theta;
  p.segment<3>(kX0) = initial;
  return p;
}

// The extensions' coefficients in p (0: the paper's model).
inline Tempcos tempcos_of(const ParamVector& p) {
  return {p[kResistanceTempcoSlot], p[kStiffnessSofteningSlot], p[kCoolingTempcoSlot]};
}

// Each extension's slot, its setting and its estimate, for code that treats them alike.
struct ExtensionSlot {
  int slot;
  ExtensionMode ExtensionSettings::*mode;
  ExtensionEstimate Extensions::*estimate;
};
inline constexpr std::array<ExtensionSlot, kExtensionSlots> kExtensionTable{
    {{kResistanceTempcoSlot, &ExtensionSettings::resistance_tempco, &Extensions::resistance_tempco},
     {kStiffnessSofteningSlot, &ExtensionSettings::stiffness_softening,
      &Extensions::stiffness_softening},
     {kCoolingTempcoSlot, &ExtensionSettings::cooling_tempco, &Extensions::cooling_tempco}}};

// The slots of the extensions `settings` does not leave out (on or auto).
inline void free_extensions(const ExtensionSettings& e, FreeMask& free) {
  free[kResistanceTempcoSlot] = e.resistance_tempco != ExtensionMode::off;
  free[kStiffnessSofteningSlot] = e.stiffness_softening != ExtensionMode::off;
  free[kCoolingTempcoSlot] = e.cooling_tempco != ExtensionMode::off;
}

inline estimator::Vector6 theta_of(const ParamVector& p) {
  return p.head<kThetaSize>();
}
inline Eigen::Vector3d initial_state_of(const ParamVector& p) {
  return p.segment<3>(kX0);
}

}  // namespace scp::refine

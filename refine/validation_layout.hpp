#pragma once
// What each block of refine/validation.hpp stores per sample (the columns of its BlockMeans):
// internal to refine/validation*.cpp.

#include <algorithm>

#include "refine/validation.hpp"

namespace scp::refine::layout {

// Both blocks.
inline constexpr int kTime = 0;      // t − t of the first sample (for the drift)
inline constexpr int kResidual = 1;  // ε
inline constexpr int kInput = 2;     // the block's input: T̄ (mechanical), V² or power (thermal)
// Mechanical block.
inline constexpr int kStiffness = 3;        // sensitivity of x to κ
inline constexpr int kThermalResidual = 4;  // ε_T through the mechanical block
inline constexpr int kMechanicalJacobian = 5;
// Thermal block.
inline constexpr int kLag = 3;         // −dT̄/dt: sensitivity of the reading to a sensor lag
inline constexpr int kResistance = 4;  // sensitivity of T̄ to ρ
inline constexpr int kCooling = 5;     // sensitivity of T̄ to γ
inline constexpr int kThermalJacobian = 6;

inline int jacobian_columns(const ValidationSettings& s) {
  return std::clamp(s.jacobian_columns, 0, kMaxJacobianColumns);
}
inline int mechanical_fields(const ValidationSettings& s) {
  return kMechanicalJacobian + jacobian_columns(s);
}
inline int thermal_fields(const ValidationSettings& s) {
  return kThermalJacobian + jacobian_columns(s);
}

}  // namespace scp::refine::layout

#pragma once
// Forward sensitivities of the model's outputs to p = [θ1..θ6, x0, ẋ0, T̄0], carried through the
// same exponential integrator as the state (refine/model_simulator.hpp).
//
// S = ∂[x, ẋ]/∂p obeys Ṡ = A(t)·S + G(t) with G = ∂(A[x, ẋ] + f)/∂p; one piece uses the state's
// e^Ω and φ1(Ω), with G taken linear between the piece's ends (trapezoid mean and chord slope).
// That is second-order accurate instead of the state's fourth: J only steers Gauss–Newton and
// feeds the covariance, while the residual, and so the fixed point of the fit, comes from the
// exact simulation. ∂T̄/∂(θ5, θ6, T̄0) is exact for the paper's model; with the extensions
// (`extended`) every ∂T̄/∂p rides on the thermal linearization's e^{−aτ} with its forcing ∂F/∂p
// linear over the piece, second order too.
//
// The outputs are x and T̄. ẋ is simulated (it is part of the state) but not fitted: a velocity
// sensor adds almost no information on θ (PAPER-NOTES), and most benches lack one.

#include "refine/landing_filter.hpp"
#include "refine/model_simulator.hpp"

namespace scp::refine {

// A sensitivity this small is 0: its products with any other entry and any channel's weight stay
// far below what the normal equations resolve, and its square stays a normal double.
inline constexpr double kNegligibleSensitivity = 1e-150;

class SensitivitySimulator {
 public:
  // thermal_only: advance T̄ and its sensitivities only (the thermal stage of the fit).
  // tc: the extensions' coefficients the model runs with; extended: also carry the sensitivities
  // to them (the slots kFirstExtensionSlot...), which a fit that holds them at 0 does not need.
  SensitivitySimulator(const Vector6& theta, const InitialState& initial, bool thermal_only = false,
                       const Tempcos& tc = {}, bool extended = false) noexcept;

  // Advances from sample `prev` to sample `cur`, the voltage switching `input_delay` later than
  // recorded (pieces_between).
  void advance(const WindowSample& prev, const WindowSample& cur,
               double input_delay = 0.0) noexcept;

  const ModelState& state() const noexcept { return state_; }
  // ∂x/∂p and ∂T̄/∂p at the current sample.
  const ParamVector& dx() const noexcept { return dx_; }
  const ParamVector& dtbar() const noexcept { return dtbar_; }
  // A measurement update with gains K = [Kx, Kẋ, KT̄] on T̄'s innovation e = T̄ measured − the
  // model's reading of T̄ (the Kalman filter of refine/landing_filter.hpp): state += K·e. With K
  // held fixed (the reference trajectory's), ∂state/∂p −= K·∂reading/∂p, `dreading` the
  // reading's sensitivity: ∂T̄/∂p through the sensor's lag, plus the ambient's offset and drift
  // where estimated. Taking ∂T̄/∂p alone left those terms' columns open-loop while the cost was
  // the filter's: steps along them lowered the cost far more than predicted, and the solver
  // crept (docs/numerics.md, "The landing filter's sensitivities").
  void correct_with_tbar(const Eigen::Vector3d& gain, double innovation,
                         const ParamVector& dreading) noexcept {
    refine::correct_with_tbar(state_, gain, innovation);
    forcing_valid_ = false;
    dx_ -= gain[0] * dreading;
    dxdot_ -= gain[1] * dreading;
    dtbar_ -= gain[2] * dreading;
    for (const int slot : kReadingSlots) reading_columns_ = reading_columns_ || dreading[slot] != 0;
  }
  // Mechanical sub-steps taken so far (refine/model_simulator.hpp, substeps()).
  long substeps_taken() const noexcept { return substeps_; }

 private:
  void advance_piece_sensitivities(const Piece& piece, const MechanicalPiece& mp,
                                   const ModelState& before) noexcept;
  void advance_thermal_sensitivities(const Piece& piece, const ThermalPiece& tp,
                                     double tbar_before) noexcept;
  void advance_extended_thermal_sensitivities(const Piece& piece, const ThermalPiece& tp,
                                              double tbar_before) noexcept;
  void advance_mechanical_sensitivities(const MechanicalPiece& mp, const ModelState& a,
                                        const Eigen::Vector3d& dtbar_a,
                                        const Eigen::Vector2d& ext_a) noexcept;
  // The same for the extensions' slots (`extended`).
  void advance_extension_sensitivities(const MechanicalPiece& mp, const ModelState& a,
                                       const Eigen::Vector2d& ext_a) noexcept;
  // The same for kReadingSlots (`reading_columns_`), whose T̄ column `reading_a` held at a.
  void advance_reading_sensitivities(const MechanicalPiece& mp, const ModelState& a,
                                     const Eigen::Vector3d& reading_a) noexcept;

  // The slots of T̄'s reading alone (the ambient's offset and drift, the sensor's lag): they reach
  // the state only through correct_with_tbar, and from there they follow the dynamics as T̄0's
  // column does (no forcing of their own).
  static constexpr std::array<int, 3> kReadingSlots{kAmbientOffsetSlot, kAmbientDriftSlot,
                                                    kSensorLagSlot};
  // The columns nothing drives after the start (the initial state's and the reading's): they
  // decay geometrically, and once subnormal a factor above 1/2 rounds an entry back to itself, so
  // it never reaches 0 and every product with it runs at a fraction of the normal speed.
  static constexpr std::array<int, 6> kDecayingSlots{
      kX0, kXdot0, kTbar0, kAmbientOffsetSlot, kAmbientDriftSlot, kSensorLagSlot};
  // Sets those columns' entries below kNegligibleSensitivity to 0.
  void flush_decayed_columns() noexcept;

  Vector6 theta_;
  SubstepRule substep_rule_;
  bool thermal_only_;
  Tempcos tc_;
  bool extended_;
  ModelState state_;
  ThermalCache cache_;
  ParamVector dx_, dxdot_, dtbar_;
  // The mechanical sensitivities' forcing G at the last piece's end (θ and the initial state's
  // slots), valid until a correction moves the state.
  Eigen::Matrix<double, kModelSlots, 1> forcing_end_;
  bool forcing_valid_ = false;
  // A correction gave kReadingSlots' columns of the state a value: they are propagated.
  bool reading_columns_ = false;
  long substeps_ = 0;
};

}  // namespace scp::refine

#include "refine/sensitivities.hpp"

namespace scp::refine {

SensitivitySimulator::SensitivitySimulator(const Vector6& theta, const InitialState& initial,
                                           bool thermal_only) noexcept
    : theta_(theta),
      thermal_only_(thermal_only),
      state_{initial[0], initial[1], initial[2]},
      dx_(ParamVector::Zero()),
      dxdot_(ParamVector::Zero()),
      dtbar_(ParamVector::Zero()) {
  dx_[kX0] = 1.0;
  dxdot_[kXdot0] = 1.0;
  dtbar_[kTbar0] = 1.0;
}

void SensitivitySimulator::advance(const WindowSample& prev, const WindowSample& cur,
                                   double input_delay) noexcept {
  Piece pieces[2];
  const int n = pieces_between(prev, cur, pieces, input_delay);
  for (int i = 0; i < n; ++i) {
    if (thermal_only_) {
      const double tbar_before = state_.tbar;
      const ThermalPiece tp = advance_thermal_piece(theta_, pieces[i], state_, cache_);
      advance_thermal_sensitivities(pieces[i], tp, tbar_before);
      continue;
    }
    const int m = substeps(theta_, state_.tbar, pieces[i].tau);
    substeps_ += m;
    for (int j = 0; j < m; ++j) {
      const Piece sub = sub_piece(pieces[i], j, m);
      const ModelState before = state_;
      const MechanicalPiece mp = advance_piece(theta_, sub, state_, cache_);
      advance_piece_sensitivities(sub, mp, before);
    }
  }
}

void SensitivitySimulator::advance_thermal_sensitivities(const Piece& piece, const ThermalPiece& tp,
                                                         double tbar_before) noexcept {
  // T̄(τ) = e^{−θ5τ}T̄(0) + τφ1(−θ5τ)·θ6·u, differentiated exactly.
  for (int p : {kCooling, kHeating, kTbar0}) dtbar_[p] *= tp.decay;
  dtbar_[kCooling] +=
      -piece.tau * tp.decay * tbar_before + tp.dinput_dtheta5(piece) * theta_[kHeating];
  dtbar_[kHeating] += tp.input(piece);
}

void SensitivitySimulator::advance_piece_sensitivities(const Piece& piece,
                                                       const MechanicalPiece& mp,
                                                       const ModelState& a) noexcept {
  using Slots = Eigen::Matrix<double, kModelSlots, 1>;  // the slots the simulation sees
  const Eigen::Vector3d dtbar_a(dtbar_[kCooling], dtbar_[kHeating], dtbar_[kTbar0]);
  advance_thermal_sensitivities(piece, mp.thermal, a.tbar);
  const ModelState& b = state_;
  const double th2 = theta_[kDampingSlope], th4 = theta_[kThermalForce];
  // G_p (second row; the first row of G is 0 because dx/dt = ẋ holds for every p); dt: ∂T̄/∂θ5,
  // ∂T̄/∂θ6, ∂T̄/∂T̄0, the only non-zero ones.
  auto forcing = [&](const ModelState& s, const Eigen::Vector3d& dt) noexcept {
    Slots g;
    g[kDamping] = -s.xdot;
    g[kDampingSlope] = -s.tbar * s.xdot;
    g[kStiffness] = -s.x;
    g[kThermalForce] = -s.tbar;
    const double through_tbar = -(th2 * s.xdot + th4);
    g[kCooling] = through_tbar * dt[0];
    g[kHeating] = through_tbar * dt[1];
    g[kX0] = 0.0;
    g[kXdot0] = 0.0;
    g[kTbar0] = through_tbar * dt[2];
    return g;
  };
  const Slots ga = forcing(a, dtbar_a);
  const Slots gb = forcing(b, Eigen::Vector3d(dtbar_[kCooling], dtbar_[kHeating], dtbar_[kTbar0]));
  // G linear over the piece (trapezoid mean ḡ, chord slope g'), then as the state's forcing:
  // w1 = (τ − kq)·ḡ, w2 = (τ − kq)·g', am = w1 − τ/2·w2 = (τ − kq)·G(0), bm = τ·w2 = (τ − kq)·ΔG,
  // the same in closed form (no quotient by τ per slot).
  const double tau = mp.tau;
  const double scale = tau - tau * tau * tau / 12.0 * mp.q;
  const Matrix2& e = mp.ef.exp;
  const Matrix2& f1 = mp.ef.phi1;
  const Matrix2& f2 = mp.ef.phi2;
  const Slots am = scale * ga;
  const Slots bm = scale * (gb - ga);
  const Slots sx = dx_.head<kModelSlots>(), sv = dxdot_.head<kModelSlots>();
  dx_.head<kModelSlots>() = e(0, 0) * sx + e(0, 1) * sv + f1(0, 1) * am + f2(0, 1) * bm;
  dxdot_.head<kModelSlots>() = e(1, 0) * sx + e(1, 1) * sv + f1(1, 1) * am + f2(1, 1) * bm;
}

}  // namespace scp::refine

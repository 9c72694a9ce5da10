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
  const ParamVector dtbar_a = dtbar_;
  advance_thermal_sensitivities(piece, mp.thermal, a.tbar);
  const ModelState& b = state_;
  const double th2 = theta_[kDampingSlope], th4 = theta_[kThermalForce];
  // G_p (second row; the first row of G is 0 because dx/dt = ẋ holds for every p).
  auto forcing = [&](const ModelState& s, const ParamVector& dt) noexcept {
    ParamVector g = ParamVector::Zero();
    g[kDamping] = -s.xdot;
    g[kDampingSlope] = -s.tbar * s.xdot;
    g[kStiffness] = -s.x;
    g[kThermalForce] = -s.tbar;
    const double through_tbar = -(th2 * s.xdot + th4);
    g[kCooling] = through_tbar * dt[kCooling];
    g[kHeating] = through_tbar * dt[kHeating];
    g[kX0] = 0.0;
    g[kXdot0] = 0.0;
    g[kTbar0] = through_tbar * dt[kTbar0];
    return g;
  };
  const ParamVector ga = forcing(a, dtbar_a);
  const ParamVector gb = forcing(b, dtbar_);
  const double tau = mp.tau;
  const double k = tau * tau * tau / 12.0;
  const Matrix2& e = mp.ef.exp;
  const Matrix2& f1 = mp.ef.phi1;
  const Matrix2& f2 = mp.ef.phi2;
  for (int p = 0; p < kModelSlots; ++p) {
    // G linear over the piece: trapezoid mean and chord slope, then as the state's forcing.
    const double gbar = 0.5 * (ga[p] + gb[p]);
    const double gslope = (gb[p] - ga[p]) / tau;
    const double w1 = tau * gbar - k * mp.q * gbar;
    const double w2 = tau * gslope - k * mp.q * gslope;
    const double am = w1 - 0.5 * tau * w2, bm = tau * w2;
    const double sx = dx_[p], sv = dxdot_[p];
    dx_[p] = e(0, 0) * sx + e(0, 1) * sv + f1(0, 1) * am + f2(0, 1) * bm;
    dxdot_[p] = e(1, 0) * sx + e(1, 1) * sv + f1(1, 1) * am + f2(1, 1) * bm;
  }
}

}  // namespace scp::refine

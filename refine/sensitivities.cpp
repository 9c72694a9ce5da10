#include "refine/sensitivities.hpp"

#include <array>
#include <cmath>

namespace scp::refine {

SensitivitySimulator::SensitivitySimulator(const Vector6& theta, const InitialState& initial,
                                           bool thermal_only, const Tempcos& tc,
                                           bool extended) noexcept
    : theta_(theta),
      substep_rule_(theta, tc.kappa),
      thermal_only_(thermal_only),
      tc_(tc),
      extended_(extended),
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
      const ThermalPiece tp = advance_thermal_piece(theta_, pieces[i], state_, cache_, tc_);
      advance_thermal_sensitivities(pieces[i], tp, tbar_before);
      continue;
    }
    const int m = substep_rule_(state_.tbar, pieces[i].tau);
    substeps_ += m;
    for (int j = 0; j < m; ++j) {
      const Piece sub = sub_piece(pieces[i], j, m);
      const ModelState before = state_;
      const MechanicalPiece mp = advance_piece(theta_, sub, state_, cache_, tc_);
      advance_piece_sensitivities(sub, mp, before);
    }
  }
  flush_decayed_columns();
}

void SensitivitySimulator::flush_decayed_columns() noexcept {
  for (const int slot : kDecayingSlots)
    for (ParamVector* column : {&dx_, &dxdot_, &dtbar_})
      if (std::abs((*column)[slot]) < kNegligibleSensitivity) (*column)[slot] = 0.0;
}

void SensitivitySimulator::advance_extended_thermal_sensitivities(const Piece& piece,
                                                                  const ThermalPiece& tp,
                                                                  double tbar_before) noexcept {
  // Ṡ_p = −a·S_p + ∂F/∂p (a at the piece's start, as the state's step), ∂F/∂p linear between
  // the piece's ends: S_p(τ) = e^{−aτ}S_p(0) + τφ1·g_p(0) + τφ2·(g_p(τ) − g_p(0)).
  const auto forcing = [this](double tbar, double u) {
    const double heat = 1.0 / (1.0 + tc_.rho * tbar);
    return Eigen::Vector4d(-(1.0 + tc_.gamma * tbar) * tbar, u * heat,
                           -theta_[kHeating] * u * tbar * heat * heat,
                           -theta_[kCooling] * tbar * tbar);
  };
  const Eigen::Vector4d g0 = forcing(tbar_before, piece.u);
  const Eigen::Vector4d g1 = forcing(state_.tbar, end_input(piece));
  const Eigen::Vector4d drive = tp.gain * g0 + tp.mean_of_input * (g1 - g0);
  constexpr std::array<int, 4> slots{kCooling, kHeating, kResistanceTempcoSlot, kCoolingTempcoSlot};
  for (std::size_t i = 0; i < slots.size(); ++i)
    dtbar_[slots[i]] = tp.decay * dtbar_[slots[i]] + drive[static_cast<Eigen::Index>(i)];
  dtbar_[kTbar0] *= tp.decay;
  if (reading_columns_)
    for (const int slot : kReadingSlots) dtbar_[slot] *= tp.decay;
}

void SensitivitySimulator::advance_thermal_sensitivities(const Piece& piece, const ThermalPiece& tp,
                                                         double tbar_before) noexcept {
  if (extended_) {
    advance_extended_thermal_sensitivities(piece, tp, tbar_before);
    return;
  }
  // T̄(τ) = e^{−θ5τ}T̄(0) + τφ1(−θ5τ)·θ6·u, differentiated exactly.
  for (int p : {kCooling, kHeating, kTbar0}) dtbar_[p] *= tp.decay;
  if (reading_columns_)
    for (const int slot : kReadingSlots) dtbar_[slot] *= tp.decay;
  dtbar_[kCooling] +=
      -piece.tau * tp.decay * tbar_before + tp.dinput_dtheta5(piece) * theta_[kHeating];
  dtbar_[kHeating] += tp.input(piece);
}

void SensitivitySimulator::advance_piece_sensitivities(const Piece& piece,
                                                       const MechanicalPiece& mp,
                                                       const ModelState& a) noexcept {
  const Eigen::Vector3d dtbar_a(dtbar_[kCooling], dtbar_[kHeating], dtbar_[kTbar0]);
  const Eigen::Vector2d ext_a(dtbar_[kResistanceTempcoSlot], dtbar_[kCoolingTempcoSlot]);
  const Eigen::Vector3d reading_a(dtbar_[kReadingSlots[0]], dtbar_[kReadingSlots[1]],
                                  dtbar_[kReadingSlots[2]]);
  advance_thermal_sensitivities(piece, mp.thermal, a.tbar);
  advance_mechanical_sensitivities(mp, a, dtbar_a, ext_a);
  if (reading_columns_) advance_reading_sensitivities(mp, a, reading_a);
}

void SensitivitySimulator::advance_reading_sensitivities(
    const MechanicalPiece& mp, const ModelState& a, const Eigen::Vector3d& reading_a) noexcept {
  const ModelState& b = state_;
  const double th2 = theta_[kDampingSlope], th3 = theta_[kStiffness], th4 = theta_[kThermalForce];
  // As T̄0's column (advance_mechanical_sensitivities): G = ∂ẍ/∂T̄ · ∂T̄/∂p, linear over the piece.
  const auto via = [&](const ModelState& s) noexcept {
    return -(th2 * s.xdot + th4) + th3 * tc_.kappa * s.x;
  };
  const double tau = mp.tau;
  const double scale = tau - tau * tau * tau / 12.0 * mp.q;
  const Matrix2& e = mp.ef.exp;
  const Matrix2& f1 = mp.ef.phi1;
  const Matrix2& f2 = mp.ef.phi2;
  for (std::size_t i = 0; i < kReadingSlots.size(); ++i) {
    const int slot = kReadingSlots[i];
    const double ga = scale * via(a) * reading_a[static_cast<Eigen::Index>(i)];
    const double gb = scale * via(b) * dtbar_[slot] - ga;
    const double sx = dx_[slot], sv = dxdot_[slot];
    dx_[slot] = e(0, 0) * sx + e(0, 1) * sv + f1(0, 1) * ga + f2(0, 1) * gb;
    dxdot_[slot] = e(1, 0) * sx + e(1, 1) * sv + f1(1, 1) * ga + f2(1, 1) * gb;
  }
}

void SensitivitySimulator::advance_mechanical_sensitivities(const MechanicalPiece& mp,
                                                            const ModelState& a,
                                                            const Eigen::Vector3d& dtbar_a,
                                                            const Eigen::Vector2d& ext_a) noexcept {
  using Slots = Eigen::Matrix<double, kModelSlots, 1>;  // θ and the initial state
  const ModelState& b = state_;
  const double th2 = theta_[kDampingSlope], th3 = theta_[kStiffness], th4 = theta_[kThermalForce];
  const double kappa = tc_.kappa;
  // ∂/∂T̄ of ẍ = −θ3(1 − κT̄)x − (θ1 + θ2T̄)ẋ − θ4T̄.
  const auto through_tbar = [&](const ModelState& s) noexcept {
    return -(th2 * s.xdot + th4) + th3 * kappa * s.x;
  };
  // G_p (second row; the first row of G is 0 because dx/dt = ẋ holds for every p); dt: ∂T̄/∂θ5,
  // ∂T̄/∂θ6, ∂T̄/∂T̄0, the only non-zero ones of θ and the initial state.
  auto forcing = [&](const ModelState& s, const Eigen::Vector3d& dt) noexcept {
    Slots g;
    g[kDamping] = -s.xdot;
    g[kDampingSlope] = -s.tbar * s.xdot;
    g[kStiffness] = -(1.0 - kappa * s.tbar) * s.x;
    g[kThermalForce] = -s.tbar;
    const double via = through_tbar(s);
    g[kCooling] = via * dt[0];
    g[kHeating] = via * dt[1];
    g[kX0] = 0.0;
    g[kXdot0] = 0.0;
    g[kTbar0] = via * dt[2];
    return g;
  };
  // G at the piece's start is G at the previous piece's end unless a correction moved the state
  // in between (correct_with_tbar).
  const Slots ga = forcing_valid_ ? forcing_end_ : forcing(a, dtbar_a);
  forcing_end_ = forcing(b, Eigen::Vector3d(dtbar_[kCooling], dtbar_[kHeating], dtbar_[kTbar0]));
  forcing_valid_ = true;
  const Slots& gb = forcing_end_;
  // G linear over the piece (trapezoid mean ḡ, chord slope g'), then as the state's forcing:
  // w1 = (τ − kq)·ḡ, w2 = (τ − kq)·g', am = w1 − τ/2·w2 = (τ − kq)·G(0), bm = τ·w2 = (τ − kq)·ΔG,
  // so that S gains φ1·am + φ2·bm = (τ − kq)·((φ1 − φ2)·G(0) + φ2·G(τ)): two products per slot
  // and row.
  const double tau = mp.tau;
  const double scale = tau - tau * tau * tau / 12.0 * mp.q;
  const Matrix2& e = mp.ef.exp;
  const Matrix2& f1 = mp.ef.phi1;
  const Matrix2& f2 = mp.ef.phi2;
  const double ax = scale * (f1(0, 1) - f2(0, 1)), bx = scale * f2(0, 1);
  const double av = scale * (f1(1, 1) - f2(1, 1)), bv = scale * f2(1, 1);
  const Slots sx = dx_.head<kModelSlots>(), sv = dxdot_.head<kModelSlots>();
  dx_.head<kModelSlots>() = e(0, 0) * sx + e(0, 1) * sv + ax * ga + bx * gb;
  dxdot_.head<kModelSlots>() = e(1, 0) * sx + e(1, 1) * sv + av * ga + bv * gb;
  if (extended_) advance_extension_sensitivities(mp, a, ext_a);
}

void SensitivitySimulator::advance_extension_sensitivities(const MechanicalPiece& mp,
                                                           const ModelState& a,
                                                           const Eigen::Vector2d& ext_a) noexcept {
  using Extension = Eigen::Matrix<double, kExtensionSlots, 1>;
  const ModelState& b = state_;
  const double th2 = theta_[kDampingSlope], th3 = theta_[kStiffness], th4 = theta_[kThermalForce];
  // The extensions' slots: ρ and γ through T̄ (ext: ∂T̄/∂ρ, ∂T̄/∂γ, times ∂ẍ/∂T̄), κ directly.
  const auto extension_forcing = [&](const ModelState& s, const Eigen::Vector2d& ext) noexcept {
    const double via = -(th2 * s.xdot + th4) + th3 * tc_.kappa * s.x;
    return Extension(via * ext[0], th3 * s.tbar * s.x, via * ext[1]);
  };
  // As the other slots' (advance_mechanical_sensitivities): am = (τ − kq)·G(0), bm = (τ − kq)·ΔG.
  const double tau = mp.tau;
  const double scale = tau - tau * tau * tau / 12.0 * mp.q;
  const Matrix2& e = mp.ef.exp;
  const Matrix2& f1 = mp.ef.phi1;
  const Matrix2& f2 = mp.ef.phi2;
  const Extension ea = scale * extension_forcing(a, ext_a);
  const Extension eb = scale * extension_forcing(b, Eigen::Vector2d(dtbar_[kResistanceTempcoSlot],
                                                                    dtbar_[kCoolingTempcoSlot])) -
                       ea;
  const Extension ex = dx_.segment<kExtensionSlots>(kFirstExtensionSlot),
                  ev = dxdot_.segment<kExtensionSlots>(kFirstExtensionSlot);
  dx_.segment<kExtensionSlots>(kFirstExtensionSlot) =
      e(0, 0) * ex + e(0, 1) * ev + f1(0, 1) * ea + f2(0, 1) * eb;
  dxdot_.segment<kExtensionSlots>(kFirstExtensionSlot) =
      e(1, 0) * ex + e(1, 1) * ev + f1(1, 1) * ea + f2(1, 1) * eb;
}

}  // namespace scp::refine

#include "refine/model_simulator.hpp"

#include <algorithm>
#include <array>
#include <cmath>

namespace scp::refine {

namespace {

// A piece of length τ over which the voltage goes from v0 at `slope`: V² = (v0 + slope·σ)².
Piece sloped_piece(double tau, double v0, double slope) noexcept {
  return {tau, v0 * v0, 2.0 * v0 * slope, slope * slope};
}

// When the voltage of `cur` landed, `input_delay` later than recorded (see pieces_between).
double switch_instant(const WindowSample& prev, const WindowSample& cur,
                      double input_delay) noexcept {
  return input_delay == 0.0 ? cur.voltage_since : std::max(cur.voltage_since, prev.t) + input_delay;
}

}  // namespace

SwitchLevels switch_levels(const WindowSample& prev, const WindowSample& cur,
                           double input_delay) noexcept {
  const double dt = cur.t - prev.t;
  const double since = switch_instant(prev, cur, input_delay);
  const double before = std::clamp(since - prev.t, 0.0, dt), after = dt - before;
  const double a = prev.voltage + cur.slope_before * before;
  const double b = cur.voltage - cur.slope_after * after;
  return {a * a, b * b};
}

int pieces_between(const WindowSample& prev, const WindowSample& cur, Piece out[2],
                   double input_delay) noexcept {
  const double dt = cur.t - prev.t;
  if (!(dt > 0.0)) return 0;
  if (cur.voltage_ramp) {
    const double a = prev.voltage, b = cur.voltage;
    if (!std::isfinite(cur.voltage_mid)) {
      const double slope = (b - a) / dt;
      out[0] = {dt, a * a, 2.0 * a * slope, slope * slope};
      return 1;
    }
    // V² through its values at the interval's start, middle and end.
    const double u0 = a * a, um = cur.voltage_mid * cur.voltage_mid, u1 = b * b;
    out[0] = {dt, u0, (4.0 * um - 3.0 * u0 - u1) / dt, 2.0 * (u0 - 2.0 * um + u1) / (dt * dt)};
    return 1;
  }
  // The previous voltage from prev.t until the switch, going on at slope_before; the new one from
  // the switch until cur.t, arriving at cur.voltage at slope_after.
  const double a = prev.voltage, slope_a = cur.slope_before;
  const double b = cur.voltage, slope_b = cur.slope_after;
  // A switch at or before the previous sample (a DAC that switches at sample instants, or −∞)
  // is one at prev.t as far as this interval can tell.
  const double since = switch_instant(prev, cur, input_delay);
  if (since > prev.t && since < cur.t) {
    out[0] = sloped_piece(since - prev.t, a, slope_a);
    out[1] = sloped_piece(cur.t - since, b - slope_b * (cur.t - since), slope_b);
    return 2;
  }
  // Not yet landed at the sample instant: the whole interval saw the previous voltage.
  out[0] =
      since >= cur.t ? sloped_piece(dt, a, slope_a) : sloped_piece(dt, b - slope_b * dt, slope_b);
  return 1;
}

int substeps(const Vector6& theta, double tbar, double tau, double kappa) noexcept {
  return SubstepRule(theta, kappa)(tbar, tau);
}

ThermalPiece thermal_piece(double theta5, double tau) noexcept {
  const double z = -theta5 * tau;
  const Phi12 p = phi12(z);
  const std::array<double, 6> f = phi_functions(z);  // φ3, φ4 for a ramp's V²
  ThermalPiece tp;
  tp.decay = std::exp(z);
  tp.gain = tau * p.phi1;
  tp.mean_of_start = p.phi1;
  tp.mean_of_input = tau * p.phi2;
  tp.dgain_dtheta5 = -tau * tau * (p.phi1 - p.phi2);
  const double t2 = tau * tau, t3 = t2 * tau;
  tp.gain1 = t2 * p.phi2;
  tp.gain2 = 2.0 * t3 * f[3];
  tp.mean1 = t2 * f[3];
  tp.mean2 = 2.0 * t3 * f[4];
  tp.dgain1 = -t3 * (p.phi2 - 2.0 * f[3]);
  tp.dgain2 = -2.0 * t3 * tau * (f[3] - 3.0 * f[4]);
  return tp;
}

ThermalStep thermal_step(const Vector6& theta, const Tempcos& tc, const Piece& piece, double tbar,
                         ThermalCache& cache, ThermalPiece& tp) noexcept {
  if (!tc.thermal()) {
    tp = cache.get(theta[kCooling], piece.tau);
    return {tp.decay * tbar + theta[kHeating] * tp.input(piece),
            tp.mean_of_start * tbar + theta[kHeating] * tp.mean(piece)};
  }
  const ThermalLinearization l = linearize_thermal(theta, tc, tbar, piece.u);
  tp = cache.get(l.a, piece.tau);
  const double ramp_end = tp.gain1 * piece.du + tp.gain2 * piece.ddu;
  const double ramp_mean = tp.mean1 * piece.du + tp.mean2 * piece.ddu;
  return {tbar + tp.gain * l.f0 + l.b * ramp_end, tbar + tp.mean_of_input * l.f0 + l.b * ramp_mean};
}

ThermalPiece advance_thermal_piece(const Vector6& theta, const Piece& piece, ModelState& state,
                                   ThermalCache& cache, const Tempcos& tc) noexcept {
  ThermalPiece tp;
  state.tbar = thermal_step(theta, tc, piece, state.tbar, cache, tp).end;
  return tp;
}

namespace {

// Ω of the fourth-order Magnus step with the stiffness θ3·(1 − κT̄) (Tempcos::kappa ≠ 0): with
// s̄ = θ3(1 − κT̄avg), α = θ3κ·dT̄/dt, A' = [[0, 0], [α, −q]] and [A', Ā] = [[−α, q], [q·s̄ + c0·α,
// α]].
Matrix2 softening_omega(double tau, double k, double c0, double q, double th3, double kappa,
                        double tavg, double tdot) noexcept {
  const double sbar = th3 * (1.0 - kappa * tavg), alpha = th3 * kappa * tdot;
  Matrix2 omega;
  omega << -k * alpha, tau + k * q, -tau * sbar + k * (q * sbar + c0 * alpha),
      -tau * c0 + k * alpha;
  return omega;
}

}  // namespace

MechanicalPiece advance_piece(const Vector6& theta, const Piece& piece, ModelState& s,
                              ThermalCache& cache, const Tempcos& tc) noexcept {
  MechanicalPiece mp;
  const double tau = piece.tau;
  const double ta = s.tbar;
  const ThermalStep step = thermal_step(theta, tc, piece, ta, cache, mp.thermal);
  const double tb = step.end, tavg = step.mean;
  // T̄ is exponential inside the piece; its slope at the middle differs from the chord's by
  // O(τ²), which enters Ω only at O(τ⁵).
  const double tdot = (tb - ta) / tau;
  const double th1 = theta[kDamping], th2 = theta[kDampingSlope], th3 = theta[kStiffness],
               th4 = theta[kThermalForce];
  mp.tau = tau;
  mp.c0 = th1 + th2 * tavg;
  mp.q = th2 * tdot;
  const double k = tau * tau * tau / 12.0;
  // [A', Ā] = q·[[0, 1], [θ3, 0]] with A' = [[0, 0], [0, −q]].
  Matrix2 omega;
  if (tc.kappa == 0.0) {
    omega << 0.0, tau + k * mp.q, -tau * th3 + k * mp.q * th3, -tau * mp.c0;
  } else {
    omega = softening_omega(tau, k, mp.c0, mp.q, th3, tc.kappa, tavg, tdot);
  }
  // f̄ = [0, −θ4 T̄avg], f' = [0, −θ4 dT̄/dt]; A'f = [0, −q·f1].
  const double fbar = -th4 * tavg, fslope = -th4 * tdot;
  const double w1 = tau * fbar - k * mp.q * fbar;
  const double w2 = tau * fslope - k * mp.q * fslope;
  mp.ef = exp_phi(omega);
  const Matrix2& e = mp.ef.exp;
  const Matrix2& f1 = mp.ef.phi1;
  const Matrix2& f2 = mp.ef.phi2;
  // Only the second component of w1, w2 is non-zero.
  const double a = w1 - 0.5 * tau * w2, b = tau * w2;
  const double x = e(0, 0) * s.x + e(0, 1) * s.xdot + f1(0, 1) * a + f2(0, 1) * b;
  const double v = e(1, 0) * s.x + e(1, 1) * s.xdot + f1(1, 1) * a + f2(1, 1) * b;
  s.x = x;
  s.xdot = v;
  s.tbar = tb;
  return mp;
}

long advance_interval(const Vector6& theta, const WindowSample& prev, const WindowSample& cur,
                      double input_delay, ModelState& state, ThermalCache& cache, double* u_end,
                      const Tempcos& tc) noexcept {
  Piece pieces[2];
  const int n = pieces_between(prev, cur, pieces, input_delay);
  long taken = 0;
  for (int i = 0; i < n; ++i) {
    const int m = substeps(theta, state.tbar, pieces[i].tau, tc.kappa);
    for (int j = 0; j < m; ++j) advance_piece(theta, sub_piece(pieces[i], j, m), state, cache, tc);
    taken += m;
    if (u_end != nullptr) *u_end = end_input(pieces[i]);
  }
  return taken;
}

void simulate(std::span<const WindowSample> window, const Vector6& theta,
              const InitialState& initial, std::span<ModelState> out, double input_delay,
              const Tempcos& tc) noexcept {
  if (window.empty() || out.size() < window.size()) return;
  ModelState s{initial[0], initial[1], initial[2]};
  out[0] = s;
  ThermalCache cache;
  for (std::size_t k = 1; k < window.size(); ++k) {
    advance_interval(theta, window[k - 1], window[k], input_delay, s, cache, nullptr, tc);
    out[k] = s;
  }
}

}  // namespace scp::refine

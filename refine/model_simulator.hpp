#pragma once
// The model of refine/fit.hpp simulated from the recorded voltage, one sample interval at a time.
//
// Thermal block, dT̄/dt = −θ5 T̄ + θ6 V²: exact for V² quadratic over a piece (the interval is cut
// at `voltage_since` when the new voltage landed inside it; each side of a switch is held or, for
// a continuous voltage, goes on at its slope).
// Mechanical block, d[x, ẋ]/dt = A(t)[x, ẋ] + f(t) with A = [[0, 1], [−θ3, −(θ1 + θ2 T̄)]] and
// f = [0, −θ4 T̄]: linear and time-varying only through T̄, which is smooth inside a piece (time
// constant 1/θ5 ≈ 17 s for the paper's actuator). Over a piece σ ∈ [0, τ], T̄ is replaced by its
// exact mean T̄avg plus its chord slope T̄'·(σ − τ/2) (the rest is O(θ5·T̄'·τ²), 1e-13 relative),
// which makes the forcing linear in σ and the system matrix A(σ) = Ā + A'·(σ − τ/2). The
// fourth-order Magnus expansion of the system augmented with [1, σ − τ/2] then gives, with
//   Ω  = τĀ + τ³/12·[A', Ā],   w1 = τf̄ + τ³/12·A'f̄,   w2 = τf' + τ³/12·A'f',
//   [x, ẋ](τ) = e^Ω [x, ẋ](0) + φ1(Ω)·(w1 − τ/2·w2) + τ·φ2(Ω)·w2:
// exact for a constant damping and a linear forcing (whatever τ·|A|, which is 1.25 for the
// paper's fast pole at 1 ms), and fourth order in the damping's change with T̄ (θ2 = α1/m).
// It agrees with the project's RK4 plant to within 1e-11 of max |x| on the paper's experiment,
// an underdamped actuator and a jittered link (tests/refine/test_model_simulator.cpp; the
// figures of this scheme and of the simpler ones it replaced: docs/numerics.md, "A consistent
// estimate"). Stable for any step: e^Ω is exact for the frozen system, so a gap in the record is
// one step.

#include <Eigen/Core>
#include <array>
#include <cmath>
#include <cstddef>
#include <span>

#include "refine/fit.hpp"
#include "refine/matrix_functions.hpp"
#include "refine/parameters.hpp"

namespace scp::refine {

struct ModelState {
  double x = 0.0, xdot = 0.0, tbar = 0.0;
};

// A stretch of an interval and its V², u + du·σ + ddu·σ² at σ ∈ [0, τ] from the piece's start:
// constant for a held voltage, quadratic for a ramp (WindowSample::voltage_ramp).
struct Piece {
  double tau = 0.0;  // s
  double u = 0.0;    // V² at the start
  double du = 0.0;   // V²/s
  double ddu = 0.0;  // V²/s²
};

// Sub-piece j of m equal ones of `piece`, its V² re-expanded about its own start.
inline Piece sub_piece(const Piece& piece, int j, int m) noexcept {
  const double h = piece.tau / m, s = h * j;
  return {h, piece.u + (piece.du + piece.ddu * s) * s, piece.du + 2.0 * piece.ddu * s, piece.ddu};
}

// V²'s mean over the piece and its value at the end.
inline double mean_input(const Piece& p) noexcept {
  return p.u + p.du * p.tau / 2.0 + p.ddu * p.tau * p.tau / 3.0;
}
inline double end_input(const Piece& p) noexcept {
  return p.u + (p.du + p.ddu * p.tau) * p.tau;
}

// The pieces from `prev` to `cur` (see WindowSample): one, or two when the switch falls strictly
// inside (prev.t, cur.t). Returns 0 when cur.t ≤ prev.t. `input_delay` (s) moves the switch
// later than recorded: at max(cur.voltage_since, prev.t) + input_delay, the voltage's timing
// relative to the samples that the fit can estimate (FitSettings::max_input_delay_s). A switch
// moved out of the interval is held at its end, and one moved before it at its start.
int pieces_between(const WindowSample& prev, const WindowSample& cur, Piece out[2],
                   double input_delay = 0.0) noexcept;

// V² of a held switch's interval just before and just after the switch (pieces_between's, with
// WindowSample::slope_before and slope_after): the step in heating that moving the switch trades.
struct SwitchLevels {
  double before = 0.0, after = 0.0;
};
SwitchLevels switch_levels(const WindowSample& prev, const WindowSample& cur,
                           double input_delay = 0.0) noexcept;

// Exact coefficients of the thermal block over a piece of length τ (z = −θ5τ):
//   T̄(τ) = decay·T̄(0) + θ6·(gain·u + gain1·du + gain2·ddu),
//   mean of T̄ = mean_of_start·T̄(0) + θ6·(mean_of_input·u + mean1·du + mean2·ddu),
// from ∫₀^τ e^{−θ5(τ−s)} s^j ds = j!·τ^{j+1}·φ_{j+1}(z), and φ_k' = φ_k − k·φ_{k+1}.
struct ThermalPiece {
  double decay = 1.0;               // e^{−θ5 τ}
  double gain = 0.0;                // τ·φ1(−θ5 τ)
  double mean_of_start = 1.0;       // φ1(−θ5 τ)
  double mean_of_input = 0.0;       // τ·φ2(−θ5 τ)
  double dgain_dtheta5 = 0.0;       // −τ²·(φ1 − φ2)(−θ5 τ), for the sensitivities
  double gain1 = 0.0, gain2 = 0.0;  // τ²·φ2, 2τ³·φ3
  double mean1 = 0.0, mean2 = 0.0;  // τ²·φ3, 2τ³·φ4
  double dgain1 = 0.0, dgain2 = 0.0;  // their ∂/∂θ5: −τ³(φ2 − 2φ3), −2τ⁴(φ3 − 3φ4)

  // ∫ e^{−θ5(τ−s)} V²(s) ds over the piece, its ∂/∂θ5, and the mean of the same over σ ∈ [0, τ].
  double input(const Piece& p) const noexcept { return gain * p.u + gain1 * p.du + gain2 * p.ddu; }
  double dinput_dtheta5(const Piece& p) const noexcept {
    return dgain_dtheta5 * p.u + dgain1 * p.du + dgain2 * p.ddu;
  }
  double mean(const Piece& p) const noexcept {
    return mean_of_input * p.u + mean1 * p.du + mean2 * p.ddu;
  }
};
ThermalPiece thermal_piece(double theta5, double tau) noexcept;

// Sub-pieces a piece is cut into so that τ·ρ(A) ≤ 1.5, ρ(A) ≤ |θ1 + θ2 T̄| + √|θ3| (the paper's
// 1 ms sample: 1.37, one sub-piece). The Magnus truncation grows like τ⁵: through a 10 ms link
// uncut pieces would leave x further from the plant than the 1e-11 that
// tests/refine/test_model_simulator.cpp allows.
// Capped at 10⁵ (a gap of minutes in a record).
// `kappa`: the stiffness's softening (Tempcos), which moves ρ(A) with T̄.
int substeps(const Vector6& theta, double tbar, double tau, double kappa = 0.0) noexcept;
inline constexpr double kMaxStiffnessPerSubstep = 1.5;  // the τ·ρ(A) bound of substeps()

// substeps() for one θ and κ, asked once per piece of a pass: √|θ3| taken once where the
// stiffness does not soften with T̄ (κ = 0), the same bits as substeps().
class SubstepRule {
 public:
  SubstepRule(const Vector6& theta, double kappa) noexcept
      : damping_(theta[kDamping]),
        slope_(theta[kDampingSlope]),
        stiffness_(theta[kStiffness]),
        kappa_(kappa),
        root_(std::sqrt(std::abs(theta[kStiffness]))) {}

  int operator()(double tbar, double tau) const noexcept {
    const double root =
        kappa_ == 0.0 ? root_ : std::sqrt(std::abs(stiffness_ * (1.0 - kappa_ * tbar)));
    const double n =
        std::ceil(tau * (std::abs(damping_ + slope_ * tbar) + root) / kMaxStiffnessPerSubstep);
    if (!(n > 1.0)) return 1;
    return n < 1e5 ? static_cast<int>(n) : 100000;
  }

 private:
  double damping_, slope_, stiffness_, kappa_, root_;
};

// The last two ThermalPieces computed, matched exactly (the same bits as computing them). A
// uniformly sampled window has one τ up to its last bits: t_k − t_{k−1} of a clock counting in
// steps of the sample interval takes two values at a time, alternating with the clock's rounding,
// where a single entry recomputed the piece (exp and the φ series) at every other sample.
class ThermalCache {
 public:
  const ThermalPiece& get(double theta5, double tau) noexcept {
    for (Entry& e : entries_)
      if (theta5 == e.theta5 && tau == e.tau) return e.piece;
    Entry& e = entries_[oldest_];
    oldest_ ^= 1;
    e.piece = thermal_piece(theta5, tau);
    e.theta5 = theta5;
    e.tau = tau;
    return e.piece;
  }

 private:
  struct Entry {
    double theta5 = -1.0, tau = -1.0;  // τ > 0 always: never a false hit
    ThermalPiece piece;
  };
  std::array<Entry, 2> entries_{};
  std::size_t oldest_ = 0;
};

// The thermal block with the extensions ρ and γ (Tempcos), dT̄/dt = F(T̄, u) with
//   F = −θ5·(1 + γT̄)·T̄ + θ6·u/(1 + ρT̄),
// linearized at the piece's start: F0 = F(T̄0, u0), a = −∂F/∂T̄, b = ∂F/∂u. The piece is then the
// exponential Rosenbrock–Euler step T̄(τ) = T̄0 + τφ1(−aτ)·F0 + b·(the input's change), second
// order in τ (T̄ changes on the thermal time constant, seconds, against a millisecond's step) and
// exact where F is linear in T̄ (ρ = γ = 0: a = θ5, the exact step above).
struct ThermalLinearization {
  double f0 = 0.0, a = 0.0, b = 0.0;
};
inline ThermalLinearization linearize_thermal(const Vector6& theta, const Tempcos& tc, double tbar,
                                              double u) noexcept {
  const double heat = 1.0 / (1.0 + tc.rho * tbar);
  ThermalLinearization l;
  l.b = theta[kHeating] * heat;
  l.f0 = -theta[kCooling] * (1.0 + tc.gamma * tbar) * tbar + l.b * u;
  l.a = theta[kCooling] * (1.0 + 2.0 * tc.gamma * tbar) + l.b * u * tc.rho * heat;
  return l;
}

// T̄ at a piece's end and its mean over the piece.
struct ThermalStep {
  double end = 0.0, mean = 0.0;
};

// One piece of the thermal block from T̄ = `tbar`; `tp` receives the ThermalPiece it used (of θ5,
// or of the linearization's a with tc.thermal()).
ThermalStep thermal_step(const Vector6& theta, const Tempcos& tc, const Piece& piece, double tbar,
                         ThermalCache& cache, ThermalPiece& tp) noexcept;

// What one mechanical step used, kept for the sensitivities that ride on it.
struct MechanicalPiece {
  ExpPhi ef;         // e^Ω, φ1(Ω), φ2(Ω)
  double tau = 0.0;  // s
  double c0 = 0.0;   // θ1 + θ2·T̄avg: the damping at the mean temperature
  double q = 0.0;    // θ2·dT̄/dt: how fast the damping changes over the piece
  ThermalPiece thermal;
};

// Advances `state` over one (sub-)piece with parameters θ and the extensions' coefficients.
MechanicalPiece advance_piece(const Vector6& theta, const Piece& piece, ModelState& state,
                              ThermalCache& cache, const Tempcos& tc = {}) noexcept;

// Advances `state` over one piece of the thermal block only (x, ẋ untouched).
ThermalPiece advance_thermal_piece(const Vector6& theta, const Piece& piece, ModelState& state,
                                   ThermalCache& cache, const Tempcos& tc = {}) noexcept;

// Advances `state` (both blocks) from sample `prev` to sample `cur`: the pieces of
// pieces_between, each cut into the sub-steps of substeps(). Returns the sub-steps taken; `u_end`
// (if given) receives V² in effect at cur.
long advance_interval(const Vector6& theta, const WindowSample& prev, const WindowSample& cur,
                      double input_delay, ModelState& state, ThermalCache& cache,
                      double* u_end = nullptr, const Tempcos& tc = {}) noexcept;

// The model's outputs at each sample of `window` (x and T̄; ẋ for tests), from `initial` at the
// first sample. `out` must hold window.size() states.
void simulate(std::span<const WindowSample> window, const Vector6& theta,
              const InitialState& initial, std::span<ModelState> out, double input_delay = 0.0,
              const Tempcos& tc = {}) noexcept;

}  // namespace scp::refine

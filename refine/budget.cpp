#include "refine/budget.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "refine/model_simulator.hpp"

namespace scp::refine {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// The work budget's model sub-steps per sample and pass, on average over the fit. 2 covers a fit
// at 1 kHz (the paper's fast pole: one sub-step per 1 ms interval) with room to spare. On a link
// the fit runs up to twice the joint stage's rounds, on intervals ten times longer cut in two at
// each landing, each piece into several sub-steps: 8 there (docs/numerics.md, "Figures behind the
// code comments").
long substeps_per_sample(const FitSettings& s) {
  return s.sample_timing_jitter ? 8 : 2;
}

// The hull of the T̄ a pass can simulate: dT̄/dt = −θ5·T̄ + θ6·V² with θ5 > 0 keeps T̄ between
// T̄0 and the steady values θ6·V²/θ5 of the window's extreme V² (a ramp's V² lies between its
// ends). {+∞, −∞} when θ5 ≤ 0 bounds nothing.
std::array<double, 2> tbar_hull(std::span<const WindowSample> w, const ParamVector& p) {
  if (!(p[kCooling] > 0.0)) return {kInf, -kInf};
  double u_lo = kInf, u_hi = 0.0;
  for (const WindowSample& s : w) {
    u_lo = std::min(u_lo, s.voltage * s.voltage);
    u_hi = std::max(u_hi, s.voltage * s.voltage);
  }
  const double gain = p[kHeating] / p[kCooling];
  return {std::min({p[kTbar0], gain * u_lo, gain * u_hi}),
          std::max({p[kTbar0], gain * u_lo, gain * u_hi})};
}

// A lower bound on the sub-steps a pass of p over w simulates: substeps() at the least ρ(A) of
// the mechanical block over the T̄ the pass can reach (|θ1 + θ2·T̄| is linear in T̄: its least
// value is at an end of the hull, or 0 where it changes sign), every interval (a piece split at a
// landing takes at least as many). Stops counting at `enough`.
long least_substeps(std::span<const WindowSample> w, const ParamVector& p, long enough) {
  const std::array<double, 2> hull = tbar_hull(w, p);
  if (!(hull[0] <= hull[1])) return 0;
  const double lo = p[kDamping] + p[kDampingSlope] * hull[0];
  const double hi = p[kDamping] + p[kDampingSlope] * hull[1];
  const double damping = lo * hi <= 0.0 ? 0.0 : std::min(std::abs(lo), std::abs(hi));
  const double rho = damping + std::sqrt(std::abs(p[kStiffness]));
  const double span = w.back().t - w.front().t;
  // Each interval takes at most one more than τ·ρ/1.5: nothing to count below that.
  if (!(rho * span / kMaxStiffnessPerSubstep + static_cast<double>(w.size()) > enough)) return 0;
  long n = 0;
  Vector6 theta = Vector6::Zero();
  theta[kStiffness] = rho * rho;  // substeps() of ρ itself, with no damping
  for (std::size_t k = 1; k < w.size() && n <= enough; ++k)
    n += substeps(theta, 0.0, w[k].t - w[k - 1].t);
  return n;
}

}  // namespace

Budget::Budget(std::span<const WindowSample> window, const FitSettings& settings)
    : max_evaluations_(std::max(1, settings.max_evaluations)),
      max_substeps_(substeps_per_sample(settings) * static_cast<long>(max_evaluations_) *
                    static_cast<long>(window.size())),
      cancel_(settings.cancel) {
  mean_interval_ = mean_sample_period(window);
}

StopReason Budget::stop() const {
  if (ended_ != StopReason::none) return ended_;
  if (cancel_ != nullptr && cancel_->load(std::memory_order_relaxed)) return StopReason::cancelled;
  if (evaluations_ >= max_evaluations_) return StopReason::evaluation_budget_spent;
  if (substeps_ >= max_substeps_) return StopReason::work_budget_spent;
  return StopReason::none;
}

bool Budget::unresolved(const ParamVector& p, double tbar_lo, double tbar_hi) const {
  const double damping = std::max(std::abs(p[kDamping] + p[kDampingSlope] * tbar_lo),
                                  std::abs(p[kDamping] + p[kDampingSlope] * tbar_hi));
  const double rho = damping + std::sqrt(std::abs(p[kStiffness]));
  return rho * mean_interval_ > kUnresolvedPolePerSample;
}

PassResult Budget::pass(std::span<const WindowSample> w, const ParamVector& p, PassSettings ps) {
  ps.cancel = cancel_;
  ps.input_delay = input_delay_;
  const double span = w.back().t - w.front().t;
  const double max_pole = kMaxPolePerSample / mean_interval_;
  ps.max_substeps = static_cast<long>(std::ceil(max_pole * span / kMaxStiffnessPerSubstep)) +
                    2 * static_cast<long>(w.size());
  ++evaluations_;
  // A model that cannot finish within max_substeps gives up anyway (too_stiff, a failed step):
  // say so before simulating up to 35 passes' worth of sub-steps. With the landing filter T̄ is
  // corrected toward the data and may leave the hull.
  if (!ps.thermal_only && !ps.landing_jitter &&
      least_substeps(w, p, ps.max_substeps) > ps.max_substeps) {
    PassResult refused;
    refused.too_stiff = true;
    return refused;
  }
  PassResult r = residual_pass(w, p, ps);
  substeps_ += r.substeps;
  return r;
}

}  // namespace scp::refine

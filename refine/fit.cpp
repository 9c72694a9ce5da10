// The staged output-error fit of refine/fit.hpp. Stages, each a Levenberg–Marquardt run on
// streamed normal equations (refine/levenberg_marquardt.hpp):
//   (a) thermal: θ5, θ6, T̄0 on T̄ alone (the thermal block does not see x);
//   (a') with FitSettings::max_input_delay_s, the voltage's delay d: the thermal stage's cost
//       profiled along d (golden section, then the parabola's vertex) and σ_d from its curvature,
//       checked by batch means (refine/delay_batch_means.hpp); every later pass switches the
//       voltage d later than recorded;
//   (b) the common scale s of θ1..θ4: scaling θ1..θ4 together changes only the weight of the
//       inertia term (the fast pole), the direction the data determine worst and the one along
//       which a biased start is off (the paper law under noise: θ1..θ4 × ~0.17). A scale search
//       means something only once the ratios are right, so first (b1) the ratios θ1, θ2, θ4
//       (θ3 held) with x0, ẋ0 are fitted at 30× the start's scale, where the model is
//       quasi-static (inertia negligible, fast pole 30× further) and the ratios are all the data
//       can see; then (b2) a 1-D search on ln s over [1/900, 1] of that: a grid at factors of 2,
//       then golden section around its best point (cost-only passes). Run when θ1..θ4 are all
//       free (with one of them known there is no common scale to search);
//   (c) mechanical: θ1..θ4, x0, ẋ0 on x with T̄ simulated from the thermal fit;
//   (d) joint: every free parameter on x and T̄ weighted by 1/σ̂², σ̂² = RSS/(N − p) per channel
//       re-estimated until it settles; with FitSettings::sample_timing_jitter, each sample weighted
//       by (Σ + s·g gᵀ)⁻¹ instead and (σ̂x², σ̂T̄², s) re-estimated by Fisher scoring, and with
//       FitSettings::outlier_threshold, from the second round on, by Hampel's robust weights too;
//       with FitSettings::landing_timing_jitter, x, ẋ and T̄ Kalman-filtered for the landings'
//       timing error (refine/landing_filter.hpp).
// Then one pass at the solution gives JᵀWJ and the score's long-run covariance (covariance.hpp):
// Newey–West's, checked by batch means.

#include "refine/fit.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "refine/covariance.hpp"
#include "refine/delay_batch_means.hpp"
#include "refine/levenberg_marquardt.hpp"
#include "refine/residual_pass.hpp"

namespace scp::refine {

namespace {

using Vector4 = Eigen::Vector4d;

struct Evaluation {
  const char* stop = nullptr;  // the fit's budget is spent or it was cancelled
  bool finite = false;
  double cost = 0.0;
  Eigen::MatrixXd normal;
  Eigen::VectorXd gradient;
  PassResult pass;
};

// The coordinates z a stage fits: p[index[i]] = z[i], or, with log_scale, z[0] = ln s and
// p[j] = base[j]·s for the scaled θ's.
struct Coordinates {
  std::vector<int> index;
  bool log_scale = false;
  std::array<bool, 4> scaled{};
  ParamVector base = ParamVector::Zero();

  Eigen::Index size() const {
    return static_cast<Eigen::Index>(index.size()) + (log_scale ? 1 : 0);
  }

  Eigen::VectorXd start() const {
    Eigen::VectorXd z(size());
    Eigen::Index o = 0;
    if (log_scale) z[o++] = 0.0;
    for (int i : index) z[o++] = base[i];
    return z;
  }

  ParamVector to_p(const Eigen::VectorXd& z) const {
    ParamVector p = base;
    Eigen::Index o = 0;
    if (log_scale) {
      const double s = std::exp(z[o++]);
      for (int j = 0; j < 4; ++j)
        if (scaled[j]) p[j] = base[j] * s;
    }
    for (int i : index) p[i] = z[o++];
    return p;
  }

  // ∂p/∂z (9 × size).
  Eigen::MatrixXd jacobian(const Eigen::VectorXd& z) const {
    Eigen::MatrixXd t = Eigen::MatrixXd::Zero(kParams, size());
    Eigen::Index o = 0;
    if (log_scale) {
      const double s = std::exp(z[0]);
      for (int j = 0; j < 4; ++j)
        if (scaled[j]) t(j, 0) = base[j] * s;
      ++o;
    }
    for (int i : index) t(i, o++) = 1.0;
    return t;
  }
};

// How stiff a model the fit simulates at all: ρ(A)·Δt ≤ 50 over the mean sample interval Δt. A
// mode that decays by e⁻⁵⁰ within one sample interval leaves nothing above rounding in the next
// sample, so beyond it the samples cannot tell one θ from another along the common scale of
// θ1..θ4 (the inertia) and the cost is flat there: without this bound Levenberg–Marquardt followed
// that valley toward m → 0, and since substeps() cuts every interval into τ·ρ/1.5 sub-steps each
// pass grew slower with the stiffness (light-stiff/N2: passes of minutes, a fit of hours).
constexpr double kMaxPolePerSample = 50.0;
// A solution whose fast pole is this far beyond the sampling (e⁻²⁰ ≈ 2e-9 left after one
// interval) sits on that flat valley: the window does not determine the common scale.
constexpr double kUnresolvedPolePerSample = 20.0;

// ρ(A) of the mechanical block at the extremes of T̄ (the bound substeps() uses).
double stiffness(const ParamVector& p, double tbar_lo, double tbar_hi) {
  const double damping = std::max(std::abs(p[0] + p[1] * tbar_lo), std::abs(p[0] + p[1] * tbar_hi));
  return damping + std::sqrt(std::abs(p[2]));
}

// Every pass of one fit goes through here: it counts the evaluations and sub-steps against
// FitSettings' bounds, polls the cancel flag, and stops a pass whose model is stiffer than
// kMaxPolePerSample.
class Budget {
 public:
  Budget(std::span<const WindowSample> window, const FitSettings& settings)
      : max_evaluations_(std::max(1, settings.max_evaluations)),
        max_substeps_(substeps_per_sample(settings) * static_cast<long>(max_evaluations_) *
                      static_cast<long>(window.size())),
        cancel_(settings.cancel) {
    const double span = window.back().t - window.front().t;
    mean_interval_ = span / static_cast<double>(window.size() - 1);
  }

  // Why the fit must stop now, or nullptr.
  const char* stop() const {
    if (cancel_ != nullptr && cancel_->load(std::memory_order_relaxed)) return "cancelled";
    if (evaluations_ >= max_evaluations_)
      return "evaluation budget spent (FitSettings::max_evaluations) before convergence";
    if (substeps_ >= max_substeps_) return "work budget spent: the model was too stiff to simulate";
    return nullptr;
  }

  PassResult pass(std::span<const WindowSample> w, const ParamVector& p, PassSettings ps) {
    ps.cancel = cancel_;
    ps.input_delay = input_delay_;
    const double span = w.back().t - w.front().t;
    ps.max_substeps = static_cast<long>(std::ceil(max_pole() * span / kMaxStiffnessPerSubstep)) +
                      2 * static_cast<long>(w.size());
    ++evaluations_;
    PassResult r = residual_pass(w, p, ps);
    substeps_ += r.substeps;
    return r;
  }

  // The work budget's sub-steps per sample and pass, on average over the fit. 2 covers a fit at
  // 1 kHz (the paper's fast pole: one sub-step per 1 ms interval) with room to spare. On a link
  // the fit runs up to 8 rounds of the joint stage instead of 4, at 100 Hz, where a 10 ms interval
  // cut in two at the landing takes ~15 sub-steps: measured, 2 stopped a converging fit ("work
  // budget spent") after 100 passes.
  static long substeps_per_sample(const FitSettings& s) { return s.sample_timing_jitter ? 8 : 2; }

  double max_pole() const { return kMaxPolePerSample / mean_interval_; }
  // Every pass from here on switches the voltage this much later than recorded.
  void set_input_delay(double d) { input_delay_ = d; }
  double input_delay() const { return input_delay_; }
  double mean_interval() const { return mean_interval_; }
  int evaluations() const { return evaluations_; }

 private:
  int max_evaluations_;
  long max_substeps_;
  const std::atomic<bool>* cancel_;
  double mean_interval_ = 1.0;
  int evaluations_ = 0;
  long substeps_ = 0;
  double input_delay_ = 0.0;
};

struct StageResult {
  ParamVector p;
  PassResult pass;
  int iterations = 0;
  bool converged = false;
  const char* message = "";
  bool stopped = false;  // the budget ran out or the fit was cancelled: the fit ends here
};

// The cost of residuals at 1e-12 of each channel's RMS: what rounding leaves on noise-free data
// (the simulator agrees with a 400-sub-step RK4 plant to 6e-13 of max |x|).
double rounding_cost(std::span<const WindowSample> w, const std::array<double, 2>& weight) {
  double sx = 0.0, st = 0.0;
  for (const WindowSample& s : w) {
    sx += s.x * s.x;
    st += s.tbar * s.tbar;
  }
  constexpr double kRelative = 1e-12;
  return kRelative * kRelative * (weight[0] * sx + weight[1] * st);
}

// The model's T̄ range over the whole window (from the thermal stage): a search on a prefix must
// not accept a damping that turns negative later in the window.
struct TbarRange {
  double lo = 0.0, hi = 0.0;
};

bool stable_at(const ParamVector& p, const PassResult& pass, const TbarRange& range);

StageResult run_stage(std::span<const WindowSample> window, const Coordinates& c,
                      const PassSettings& pass_settings, int max_iterations, Budget& budget,
                      const TbarRange& range = {}) {
  const double cost_floor = rounding_cost(
      window,
      {pass_settings.thermal_only ? 0.0 : pass_settings.weight[0], pass_settings.weight[1]});
  auto evaluate = [&](const Eigen::VectorXd& z) {
    Evaluation e;
    if ((e.stop = budget.stop()) != nullptr) return e;
    const ParamVector p = c.to_p(z);
    // A non-finite θ is a failed step, never a simulation.
    if (!z.allFinite() || !p.allFinite()) return e;
    e.pass = budget.pass(window, p, pass_settings);
    // An unstable model (negative damping at some T̄ of the window, θ3 or θ5 ≤ 0) counts as not
    // finite: the solver backs off instead of following a diverging simulation.
    e.finite = e.pass.finite && std::isfinite(e.pass.cost) &&
               (pass_settings.thermal_only ? p[4] > 0.0 : stable_at(p, e.pass, range));
    e.cost = e.pass.cost;
    const Eigen::MatrixXd t = c.jacobian(z);
    e.normal = t.transpose() * e.pass.jtwj * t;
    e.gradient = t.transpose() * e.pass.jtwr;
    return e;
  };
  LmSettings lm;
  lm.max_iterations = max_iterations;
  lm.observations = static_cast<double>(window.size()) *
                    ((pass_settings.weight[0] > 0.0 && !pass_settings.thermal_only ? 1.0 : 0.0) +
                     (pass_settings.weight[1] > 0.0 ? 1.0 : 0.0));
  lm.cost_floor = cost_floor;
  auto out = levenberg_marquardt<Evaluation>(evaluate, c.start(), lm);
  StageResult r;
  r.p = c.to_p(out.z);
  r.pass = std::move(out.at_z.pass);
  r.iterations = out.iterations;
  r.converged = out.converged;
  r.message = out.message;
  r.stopped = budget.stop() != nullptr;
  return r;
}

const char* check_window(std::span<const WindowSample> w) {
  if (w.size() < 3) return "window has fewer than 3 samples";
  for (std::size_t k = 0; k < w.size(); ++k) {
    const WindowSample& s = w[k];
    if (!std::isfinite(s.t) || !std::isfinite(s.x) || !std::isfinite(s.tbar) ||
        !std::isfinite(s.voltage) || std::isnan(s.voltage_since))
      return "window has a non-finite sample";
    if (k > 0 && !(s.t > w[k - 1].t)) return "window times are not strictly increasing";
  }
  return nullptr;
}

// θ5, θ6 from dT̄/dt ≈ −θ5·T̄ + θ6·V² by least squares on sample differences: biased by noise on
// T̄ only as much as the noise is against T̄'s range, plenty for a start.
void thermal_from_data(std::span<const WindowSample> w, double& theta5, double& theta6) {
  Eigen::Matrix2d a = Eigen::Matrix2d::Zero();
  Eigen::Vector2d b = Eigen::Vector2d::Zero();
  for (std::size_t k = 1; k < w.size(); ++k) {
    const double dt = w[k].t - w[k - 1].t;
    const Eigen::Vector2d row(-0.5 * (w[k].tbar + w[k - 1].tbar), w[k].voltage * w[k].voltage);
    const double y = (w[k].tbar - w[k - 1].tbar) / dt;
    // Weighted by dt² so that the sum is over equation-error per interval, not per second⁻¹.
    a.noalias() += dt * dt * row * row.transpose();
    b.noalias() += dt * dt * row * y;
  }
  const Eigen::Vector2d th = a.ldlt().solve(b);
  theta5 = th.allFinite() && th[0] > 0.0 ? th[0] : 0.05;
  theta6 = th.allFinite() && th[1] > 0.0 ? th[1] : 1.0;
}

// Channel variance floor: a noise-free record must not give infinite weights.
double variance_floor(std::span<const WindowSample> w, int channel) {
  double ss = 0.0;
  for (const WindowSample& s : w) ss += channel == 0 ? s.x * s.x : s.tbar * s.tbar;
  const double rms = std::sqrt(ss / static_cast<double>(w.size()));
  const double floor = 1e-15 * rms;
  return std::max(floor * floor, std::numeric_limits<double>::min());
}

// Degrees of freedom left in a channel of n samples with p parameters acting on it.
double dof(std::size_t n, std::size_t p) {
  return std::max(1.0, static_cast<double>(n) - static_cast<double>(p));
}

bool stable_at(const ParamVector& p, const PassResult& pass, const TbarRange& range) {
  if (!(p[4] > 0.0) || !(p[2] > 0.0)) return false;
  const double lo = std::min(pass.tbar_min, range.lo), hi = std::max(pass.tbar_max, range.hi);
  return p[0] + p[1] * lo > 0.0 && p[0] + p[1] * hi > 0.0;
}

// How far before its recorded instant a switch can be moved (a negative delay): as far as the
// earliest switch recorded inside its interval allows, at most `limit`. A DAC that switches at
// the samples records its switches there, and one cannot move into the interval before (the
// command was computed from that sample: causality says d ≥ 0 there).
double earliest_switch_delay(std::span<const WindowSample> w, double limit) {
  double lead = limit;
  bool inside = false;
  for (std::size_t k = 1; k < w.size(); ++k) {
    const double since = w[k].voltage_since;
    if (since > w[k - 1].t && since < w[k].t) {
      lead = std::min(lead, since - w[k - 1].t);
      inside = true;
    }
  }
  return inside ? lead : 0.0;
}

// The thermal stage's coordinates (θ5, θ6 unless known, T̄0) from `base`, and its passes: T̄ alone.
Coordinates thermal_coordinates(const std::array<bool, 6>& known, const ParamVector& base) {
  Coordinates c;
  for (int i : {4, 5})
    if (!known[i]) c.index.push_back(i);
  c.index.push_back(kTbar0);
  c.base = base;
  return c;
}

PassSettings thermal_pass() {
  PassSettings ps;
  ps.weight = {0.0, 1.0};
  ps.thermal_only = true;
  return ps;
}

struct GoldenResult {
  double x = 0.0;
  double cost = 0.0;
};

// Golden-section search for the minimum of `cost` on [a, b] until the bracket is narrower than
// `tolerance` (at most max_steps steps, fewer when `stop` says so); `steps` counts them.
template <class Cost, class Stop>
GoldenResult golden_section(double a, double b, double tolerance, int max_steps, Cost&& cost,
                            Stop&& stop, int& steps) {
  const double g = 0.5 * (std::sqrt(5.0) - 1.0);
  double x1 = b - g * (b - a), x2 = a + g * (b - a);
  double f1 = cost(x1), f2 = cost(x2);
  for (int i = 0; i < max_steps && b - a > tolerance && !stop(); ++i) {
    ++steps;
    if (f1 < f2) {
      b = x2;
      x2 = x1;
      f2 = f1;
      x1 = b - g * (b - a);
      f1 = cost(x1);
    } else {
      a = x1;
      x1 = x2;
      f1 = f2;
      x2 = a + g * (b - a);
      f2 = cost(x2);
    }
  }
  return f1 < f2 ? GoldenResult{x1, f1} : GoldenResult{x2, f2};
}

struct DelayEstimate {
  bool ok = false;
  double delay = 0.0;            // s
  double sigma = 0.0;            // s, after the batch-means check
  double sigma_inflation = 1.0;  // what the check scaled σ_d by
  bool at_limit = false;
  ParamVector p = ParamVector::Zero();  // the thermal fit at `delay`
};

// σ_d checked by batch means (refine/delay_batch_means.hpp): three thermal passes at the profile's
// (θ5, θ6, T̄0), weighted by T̄'s residual variance `var_t` there, with d at d̂ and d̂ ± σ_d (the
// profile is a parabola that far); d rides in θ1's slot, which the thermal stage leaves fixed.
void check_delay(std::span<const WindowSample> window, const Coordinates& c, DelayEstimate& out,
                 double lowest, double var_t, Budget& budget, const FitSettings& settings) {
  const double h = out.sigma;
  if (!(h > 0.0) || !(var_t > 0.0) || out.delay - h < lowest) return;
  FreeMask free{};
  for (const int i : c.index) free[static_cast<std::size_t>(i)] = true;
  PassSettings ps = thermal_pass();
  ps.batches = settings.covariance_batches;
  ps.weight[1] = 1.0 / var_t;
  budget.set_input_delay(out.delay);
  const PassResult weighted = budget.pass(window, out.p, ps);
  budget.set_input_delay(out.delay - h);
  const PassResult below = budget.pass(window, out.p, ps);
  budget.set_input_delay(out.delay + h);
  const PassResult above = budget.pass(window, out.p, ps);
  budget.set_input_delay(out.delay);
  constexpr std::size_t kDelaySlot = 0;
  const BatchMeansCheck check =
      check_delay_against_batch_means(below, weighted, above, h, free, kDelaySlot);
  out.sigma_inflation = check.factor[kDelaySlot];
  out.sigma *= out.sigma_inflation;
}

// The voltage's delay d from T̄ alone (FitSettings::max_input_delay_s): the profile of the thermal
// cost, (θ5, θ6, T̄0) refitted at each d, minimized by golden section over [−limit, limit] (it is
// a parabola near its minimum: T̄'s error is linear in a small shift of V²), then σ_d from its
// curvature, Δχ² = 1. Its passes are thermal-only (no mechanical sub-steps, ~1/10 of a
// mechanical pass) and count against a budget of their own, so that a fit with a delay to find
// has the same budget left for θ1..θ4 as one without.
DelayEstimate estimate_input_delay(std::span<const WindowSample> window, const ParamVector& start,
                                   const std::array<bool, 6>& known, double limit, int max_it,
                                   const FitSettings& settings) {
  FitSettings own = settings;
  own.max_evaluations = 2000;
  Budget budget(window, own);
  Coordinates c = thermal_coordinates(known, start);
  const PassSettings ps = thermal_pass();
  const double inf = std::numeric_limits<double>::infinity();
  DelayEstimate out;
  out.p = start;
  double best_cost = inf;
  // The thermal fit at d, started from the best one so far (a few iterations each).
  auto fit_at = [&](double d, ParamVector& p_at) {
    budget.set_input_delay(d);
    if (budget.stop() != nullptr) return inf;
    c.base = out.p;
    const StageResult r = run_stage(window, c, ps, max_it, budget);
    p_at = r.p;
    return r.pass.finite ? r.pass.cost : inf;
  };
  auto cost_at = [&](double d) {
    ParamVector p_at = out.p;
    const double cost = fit_at(d, p_at);
    if (cost < best_cost) {
      best_cost = cost;
      out.delay = d;
      out.p = p_at;
    }
    return cost;
  };
  // Golden section to 0.5 µs, then the vertex of the parabola the curvature is measured on: T̄
  // resolves d to ~0.3 µs on a clean link (docs/numerics.md).
  const double lowest = -earliest_switch_delay(window, limit);
  int steps = 0;
  golden_section(
      lowest, limit, 0.5e-6, 80, cost_at, [&] { return budget.stop() != nullptr; },
      steps);  // cost_at keeps the best point it has seen
  if (!std::isfinite(best_cost) || budget.stop() != nullptr) return out;
  double d = out.delay;
  // Curvature over ±h with h near σ_d itself (the parabola is exact there; far smaller steps
  // drown in the solver's tolerance), Δχ² = 1 at σ_d; a side beyond the search range is the
  // range's end.
  double h = std::min(1e-6, limit / 4);
  for (int round = 0; round < 8 && budget.stop() == nullptr; ++round) {
    const double c0 = best_cost;
    const double var_t = c0 / dof(window.size(), c.index.size() + 1);
    const double lo = std::max(lowest, d - h), hi = std::min(limit, d + h);
    const double cm = lo < d ? cost_at(lo) : c0, cp = hi > d ? cost_at(hi) : c0;
    // The parabola through (lo, cm), (d, c0), (hi, cp).
    const double sl = (c0 - cm) / std::max(d - lo, 1e-300),
                 sr = (cp - c0) / std::max(hi - d, 1e-300);
    const double curvature = 2.0 * (sr - sl) / std::max(hi - lo, 1e-300);
    if (!(curvature > 0.0) || !std::isfinite(curvature) || lo >= hi) {
      h *= 10.0;  // flat at this scale: the noise hides d more than that
      if (h > limit) break;
      continue;
    }
    out.sigma = std::sqrt(2.0 * var_t / curvature);
    out.ok = true;
    const double vertex = 0.5 * (lo + hi) - 0.5 * (sl + sr) / curvature;
    const bool settled = out.sigma < 4.0 * h && out.sigma > 0.25 * h;
    if (settled && vertex > lo && vertex < hi) {
      ParamVector p_at = out.p;
      const double cv = fit_at(vertex, p_at);
      if (cv <= best_cost) {
        best_cost = cv;
        out.delay = d = vertex;
        out.p = p_at;
      }
    }
    if (settled) break;
    h = std::clamp(out.sigma, 1e-9, limit / 4);
    d = out.delay;
  }
  out.at_limit = std::abs(out.delay) > limit * (1.0 - 1e-6);
  if (out.ok && settings.covariance_batches > 1) {
    // best_cost is the weight-1 cost at (d̂, out.p): T̄'s residual variance, as σ_d's own.
    const double var_t = best_cost / dof(window.size(), c.index.size() + 1);
    check_delay(window, c, out, lowest, var_t, budget, settings);
  }
  return out;
}

}  // namespace

FitResult fit(std::span<const WindowSample> window, const Vector6& theta_start,
              const FitSettings& settings) {
  FitResult result;
  result.theta = theta_start;
  if (const char* why = check_window(window)) {
    result.message = why;
    return result;
  }
  const std::size_t n = window.size();
  result.samples = n;
  result.t_begin = window.front().t;
  result.t_end = window.back().t;
  const auto& known = settings.known;
  const int max_it = std::max(1, settings.max_iterations);

  ParamVector p = ParamVector::Zero();
  p.head<6>() = theta_start;
  p[kX0] = window.front().x;
  p[kXdot0] = 0.0;
  p[kTbar0] = window.front().tbar;
  // Start values the caller left unusable (zero, negative, non-finite) come from the data.
  double th5 = 0.0, th6 = 0.0;
  const bool thermal_usable =
      std::isfinite(p[4]) && std::isfinite(p[5]) && p[4] > 0.0 && p[5] > 0.0;
  if (!thermal_usable) {
    thermal_from_data(window, th5, th6);
    if (!known[4]) p[4] = th5;
    if (!known[5]) p[5] = th6;
  }
  const bool mechanical_usable = p.head<4>().allFinite() && p[0] > 0.0 && p[2] > 0.0;
  if (!mechanical_usable) {
    // A default shape: poles at −1 and −1000 rad/s at scale 1, no temperature-dependent damping,
    // and the static gain x ≈ −(θ4/θ3)·T̄ fitted to the data; stage (b) then finds the scale.
    double xt = 0.0, tt = 0.0;
    for (const WindowSample& s : window) {
      xt += s.x * s.tbar;
      tt += s.tbar * s.tbar;
    }
    const double gain = tt > 0.0 ? -xt / tt : 0.0;
    const double shape[4] = {1001.0, 0.0, 1000.0, gain * 1000.0};
    for (int j = 0; j < 4; ++j)
      if (!known[j]) p[j] = shape[j];
  }
  if (!p.allFinite()) {
    result.message = "start not finite";
    return result;
  }

  int iterations = 0;
  Budget budget(window, settings);
  // Ends the fit early (cancelled, budget spent) with θ where it got to.
  auto stopped_here = [&](const char* why) {
    result.iterations = iterations;
    result.evaluations = budget.evaluations();
    result.theta = p.head<6>();
    result.initial_state = p.tail<3>();
    result.message = why;
    return result;
  };
  double var_x = 1.0, var_t = 1.0;
  const double floor_x = variance_floor(window, 0), floor_t = variance_floor(window, 1);

  TbarRange range;
  bool delay_at_limit = false;
  // (a) thermal.
  {
    const Coordinates c = thermal_coordinates(known, p);
    const StageResult r = run_stage(window, c, thermal_pass(), max_it, budget);
    iterations += r.iterations;
    if (r.pass.finite) {
      p = r.p;
      var_t = std::max(r.pass.rss[1] / dof(n, c.index.size()), floor_t);
      range = {r.pass.tbar_min, r.pass.tbar_max};
    }
    if (r.stopped) return stopped_here(budget.stop());
  }
  // (a') the voltage's delay, when its timing is not trusted (FitSettings::max_input_delay_s).
  if (settings.max_input_delay_s > 0.0) {
    const DelayEstimate de =
        estimate_input_delay(window, p, known, settings.max_input_delay_s, max_it, settings);
    if (settings.cancel != nullptr && settings.cancel->load(std::memory_order_relaxed))
      return stopped_here("cancelled");
    if (!de.ok) {
      result.message = "the voltage's delay could not be estimated from T (no heating?)";
      return stopped_here(result.message);
    }
    p = de.p;
    budget.set_input_delay(de.delay);
    result.input_delay_estimated = true;
    result.input_delay_s = de.delay;
    result.input_delay_sigma_s = de.sigma;
    result.input_delay_sigma_inflation = de.sigma_inflation;
    delay_at_limit = de.at_limit;
  }
  // A start whose damping θ1 + θ2·T̄ turns negative somewhere in the thermal fit's T̄ range
  // cannot be simulated (the paper law under noise gives such θ̂: light-stiff/N2 had θ̂2 = −0.16
  // with θ̂1 = 3.6, negative above T̄ = 22 °C, and every stage then stopped at its start). α1 is a
  // small modulation of the damping: start without it and let the fit find it.
  if (!known[1] && !(p[0] + p[1] * range.lo > 0.0 && p[0] + p[1] * range.hi > 0.0)) p[1] = 0.0;
  bool all_mechanical_free = true;
  for (int j = 0; j < 4; ++j) all_mechanical_free = all_mechanical_free && !known[j];
  if (all_mechanical_free) {
    // Both searches only need to land in the basin of (c): the first 60 s are enough (the paper's
    // fast sine pair has 6 periods in them) and cost a fifth of a 300 s window.
    constexpr double kSearchSeconds = 60.0;
    std::size_t prefix = 3;
    while (prefix < n && window[prefix].t - window.front().t <= kSearchSeconds) ++prefix;
    const auto head = window.first(prefix);
    // (b1) ratios at a quasi-static scale.
    constexpr double kQuasiStatic = 30.0;
    const Vector4 theta_before_search = p.head<4>();
    p.head<4>() *= kQuasiStatic;
    Coordinates c;
    c.index = {0, 1, 3, kX0, kXdot0};
    c.base = p;
    PassSettings ps;
    ps.weight = {1.0, 0.0};
    const StageResult r = run_stage(head, c, ps, std::min(max_it, 50), budget, range);
    iterations += r.iterations;
    if (r.pass.finite) p = r.p;
    if (r.stopped) return stopped_here(budget.stop());
    // (b2) the scale.
    ps.jacobian = false;
    auto cost_at = [&](double ln_s) {
      ParamVector q = p;
      q.head<4>() *= std::exp(ln_s);
      if (!q.allFinite() || budget.stop() != nullptr)
        return std::numeric_limits<double>::infinity();
      const PassResult pr = budget.pass(head, q, ps);
      return pr.finite && stable_at(q, pr, range) ? pr.cost
                                                  : std::numeric_limits<double>::infinity();
    };
    const double ln2 = std::log(2.0);
    const double lo = -std::log(kQuasiStatic * kQuasiStatic);
    double best_ln = 0.0, best_cost = cost_at(0.0);
    // Both loops are bounded by their counts, not by floating-point comparisons alone.
    const int grid_points = static_cast<int>(std::floor(-lo / ln2 + 1e-9));
    for (int i = 1; i <= grid_points && budget.stop() == nullptr; ++i) {
      const double ln_s = -ln2 * i;
      const double cost = cost_at(ln_s);
      ++iterations;
      if (cost < best_cost) {
        best_cost = cost;
        best_ln = ln_s;
      }
    }
    // Golden section on [best − ln 2, best + ln 2] (clipped to the searched range).
    const GoldenResult golden = golden_section(
        std::max(lo, best_ln - ln2), std::min(0.0, best_ln + ln2), 0.05, 64, cost_at,
        [&] { return budget.stop() != nullptr; }, iterations);
    if (golden.cost < best_cost) best_ln = golden.x;
    p.head<4>() *= std::exp(best_ln);
    // A start that already fits better (the previous window's refined θ, an underdamped
    // actuator whose quasi-static ratios mislead) is kept.
    ParamVector q = p;
    q.head<4>() = theta_before_search;
    const PassResult at_start = budget.pass(head, q, ps);
    ++iterations;
    if (at_start.finite && stable_at(q, at_start, range) &&
        at_start.cost < std::min(best_cost, golden.cost))
      p = q;
    if (budget.stop() != nullptr) return stopped_here(budget.stop());
  }
  // (c) mechanical.
  {
    Coordinates c;
    for (int j = 0; j < 4; ++j)
      if (!known[j]) c.index.push_back(j);
    c.index.push_back(kX0);
    c.index.push_back(kXdot0);
    c.base = p;
    PassSettings ps;
    ps.weight = {1.0, 0.0};
    const StageResult r = run_stage(window, c, ps, max_it, budget, range);
    iterations += r.iterations;
    if (r.pass.finite) {
      p = r.p;
      var_x = std::max(r.pass.rss[0] / dof(n, c.index.size()), floor_x);
    }
    if (r.stopped) return stopped_here(budget.stop());
  }
  // (d) joint, with σ̂² re-estimated from the residuals until it settles.
  FreeMask free{};
  for (int i = 0; i < 6; ++i) free[i] = !known[i];
  free[kX0] = free[kXdot0] = free[kTbar0] = true;
  std::size_t free_x = 0, free_t = 1;
  for (int i = 0; i < 6; ++i) free_x += free[i] ? 1 : 0;
  free_x += 3;
  free_t += (free[4] ? 1 : 0) + (free[5] ? 1 : 0);
  StageResult joint;
  // With the samples' timing jitter (FitSettings::sample_timing_jitter) its variance s is
  // estimated with the two noise variances by Fisher scoring, from s = 0 (the first step is then
  // the moment estimate); EM would crawl toward a noise variance near 0 (noise-free sensors),
  // halving it each round.
  const bool timing = settings.sample_timing_jitter;
  double timing_var = 0.0;
  // Robust weights (FitSettings::outlier_threshold) once s has been estimated: before that every
  // sample with a large velocity would look like an outlier.
  bool timing_estimated = false;
  const auto timing_settings = [&](PassSettings& ps) {
    ps.timing = timing;
    ps.timing_variance = timing_var;
    ps.timing_reference = p;
    if (timing && timing_estimated) ps.outlier_threshold = settings.outlier_threshold;
    ps.landing_jitter = timing && settings.landing_timing_jitter;
  };
  const int rounds = timing ? 8 : 4;
  for (int round = 0; round < rounds; ++round) {
    Coordinates c;
    for (int i = 0; i < kParams; ++i)
      if (free[i]) c.index.push_back(i);
    c.base = p;
    PassSettings ps;
    ps.weight = {1.0 / var_x, 1.0 / var_t};
    timing_settings(ps);
    joint = run_stage(window, c, ps, max_it, budget, range);
    iterations += joint.iterations;
    if (joint.pass.finite) p = joint.p;
    if (joint.stopped) return stopped_here(budget.stop());
    if (!joint.pass.finite) break;
    double new_var_x = std::max(joint.pass.rss[0] / dof(n, free_x), floor_x);
    double new_var_t = std::max(joint.pass.rss[1] / dof(n, free_t), floor_t);
    bool settled =
        std::abs(new_var_x / var_x - 1.0) < 0.02 && std::abs(new_var_t / var_t - 1.0) < 0.02;
    if (timing) {
      const Eigen::Vector3d v(var_x, var_t, timing_var);
      const Eigen::Vector3d step =
          joint.pass.variance_information.ldlt().solve(joint.pass.variance_score);
      Eigen::Vector3d next = v;
      if (step.allFinite()) next += step;
      // A step can overshoot toward 0: at most a factor 10 down per round, never below the floors.
      new_var_x = std::max({next[0], 0.1 * var_x, floor_x});
      new_var_t = std::max({next[1], 0.1 * var_t, floor_t});
      const double new_s = std::max({next[2], 0.1 * timing_var, 0.0});
      // A noise variance below 1 % of what the timing error puts into its channel no longer moves
      // the weights (noise-free sensors: it wanders near its floor).
      const auto variance_settled = [&](double before, double after, int ch) {
        const double timing_share =
            new_s * joint.pass.speed_squares[static_cast<std::size_t>(ch)] / static_cast<double>(n);
        return std::abs(after / before - 1.0) < 0.02 ||
               std::max(before, after) < 0.01 * timing_share;
      };
      settled = variance_settled(var_x, new_var_x, 0) && variance_settled(var_t, new_var_t, 1) &&
                std::abs(new_s - timing_var) <= 0.02 * std::max(new_s, timing_var);
      timing_var = new_s;
      // The first round with robust weights changes the cost: not settled yet.
      if (!timing_estimated && settings.outlier_threshold > 0.0) settled = false;
      timing_estimated = true;
    }
    var_x = new_var_x;
    var_t = new_var_t;
    if (settled) break;
  }
  result.sample_timing_sigma_s = std::sqrt(timing_var);
  result.iterations = iterations;
  result.evaluations = budget.evaluations();
  result.theta = p.head<6>();
  result.initial_state = p.tail<3>();
  if (!joint.pass.finite || !p.allFinite()) {
    result.message = "model not finite";
    return result;
  }

  // Covariance at the solution with the final σ̂.
  const double rho_x = joint.pass.rss[0] > 0.0 ? joint.pass.lag1[0] / joint.pass.rss[0] : 0.0;
  const double rho_t = joint.pass.rss[1] > 0.0 ? joint.pass.lag1[1] / joint.pass.rss[1] : 0.0;
  // A caller's lag count beyond a quarter of the window would leave too few batches to average.
  const int max_lags = static_cast<int>(std::max<std::size_t>(1, n / 4));
  const int lags = settings.hac_lags > 0 ? std::min(settings.hac_lags, max_lags)
                                         : automatic_hac_lags(n, std::max(rho_x, rho_t));
  PassSettings ps;
  ps.weight = {1.0 / var_x, 1.0 / var_t};
  timing_settings(ps);
  ps.hac_bandwidth = lags + 1;
  ps.batches = settings.covariance_batches;
  const PassResult final_pass = budget.pass(window, p, ps);
  result.evaluations = budget.evaluations();
  if (final_pass.cancelled) return stopped_here("cancelled");
  ParamMatrix white = ParamMatrix::Zero(), hac = ParamMatrix::Zero();
  const bool white_ok = final_pass.finite && inverse_on_free(final_pass.jtwj, free, white);
  const bool hac_ok = white_ok && sandwich_on_free(final_pass.jtwj, final_pass.long_run, free, hac);
  result.hac_lags = lags;
  result.outliers = final_pass.outliers;
  result.covariance_white = white.topLeftCorner<6, 6>();
  if (hac_ok) {
    const BatchMeansCheck check = check_against_batch_means(
        hac, final_pass.jtwj, final_pass.batch_scores, final_pass.batch_information, free);
    result.sigma_inflation = check.factor.head<6>();
    result.batch_ratio = check.ratio.head<6>();
    result.batch_dof = check.dof.head<6>();
  }
  result.covariance = hac.topLeftCorner<6, 6>();
  if (result.input_delay_estimated && white_ok && result.input_delay_sigma_s > 0.0) {
    // What σ_d does to θ: the Gauss–Newton step from this solution to the fit at d̂ + σ_d (one
    // pass), added to the covariance as an independent error (the delay comes from T̄'s fit,
    // whose noise the rest of the covariance already counts only through θ5, θ6).
    PassSettings shifted = ps;
    shifted.hac_bandwidth = 0;
    budget.set_input_delay(result.input_delay_s + result.input_delay_sigma_s);
    const PassResult sp = budget.pass(window, p, shifted);
    budget.set_input_delay(result.input_delay_s);
    if (sp.cancelled) return stopped_here("cancelled");
    if (sp.finite) {
      const Vector6 shift = (white * (sp.jtwr - final_pass.jtwr)).head<6>();
      result.covariance_white += shift * shift.transpose();
      result.covariance += shift * shift.transpose();
    }
  }
  result.sigma_white = result.covariance_white.diagonal().cwiseMax(0.0).cwiseSqrt();
  result.sigma = result.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  result.residual_rms = Vector2(std::sqrt(final_pass.rss[0] / static_cast<double>(n)),
                                std::sqrt(final_pass.rss[1] / static_cast<double>(n)));
  // The sensor noise alone: with the timing jitter estimated, its variance components.
  result.noise_sigma = timing ? Vector2(std::sqrt(var_x), std::sqrt(var_t))
                              : Vector2(std::sqrt(final_pass.rss[0] / dof(n, free_x)),
                                        std::sqrt(final_pass.rss[1] / dof(n, free_t)));
  const bool stable = stable_at(p, final_pass, range);
  const bool resolved = stiffness(p, std::min(final_pass.tbar_min, range.lo),
                                  std::max(final_pass.tbar_max, range.hi)) *
                            budget.mean_interval() <=
                        kUnresolvedPolePerSample;
  result.converged = joint.converged && stable && hac_ok && resolved && !delay_at_limit;
  if (!stable)
    result.message = "model unstable at the fit";
  else if (!resolved)
    result.message =
        "the fitted fast mechanical pole is far beyond the sampling: this window does not "
        "determine the common scale of theta1..theta4 (the inertia)";
  else if (!hac_ok)
    result.message = "covariance singular: a free parameter is not excited";
  else if (delay_at_limit)
    result.message =
        "the voltage's delay is at the search limit (FitSettings::max_input_delay_s): its timing "
        "is off by more than that";
  else
    result.message = joint.message;
  return result;
}

}  // namespace scp::refine

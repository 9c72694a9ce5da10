#include "refine/stage.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "refine/levenberg_marquardt.hpp"

namespace scp::refine {

namespace {

struct Evaluation {
  const char* stop = nullptr;  // the fit's budget is spent or it was cancelled
  bool finite = false;
  bool unresolved = false;  // refine/levenberg_marquardt.hpp's runs_past_resolution()
  bool too_stiff = false;
  double cost = 0.0;
  Eigen::MatrixXd normal;
  Eigen::VectorXd gradient;
  PassResult pass;
  std::shared_ptr<ResidualValidator> validator;  // StageOptions::trial_covariance

  // The one-step rule's accepted start (refine/levenberg_marquardt.hpp): the cost and the
  // residuals' sums of squares are the step's, the rest the start's.
  void adopt_cost(const Evaluation& at_step) {
    cost = at_step.cost;
    pass.cost = at_step.pass.cost;
    pass.rss = at_step.pass.rss;
  }
};

// The cost of residuals at 1e-12 of each channel's RMS: what rounding leaves on noise-free data
// (the simulator agrees with a 400-sub-step RK4 plant to rounding,
// tests/refine/test_model_simulator.cpp).
double rounding_cost(std::span<const WindowSample> w, const std::array<double, 2>& weight) {
  double sx = 0.0, st = 0.0;
  for (const WindowSample& s : w) {
    sx += s.x * s.x;
    st += s.tbar * s.tbar;
  }
  constexpr double kRelative = 1e-12;
  return kRelative * kRelative * (weight[0] * sx + weight[1] * st);
}

}  // namespace

Coordinates::Coordinates(const FreeMask& free, const ParamVector& base_p) : base(base_p) {
  for (int i = 0; i < kParams; ++i)
    if (free[static_cast<std::size_t>(i)]) index.push_back(i);
}

Eigen::VectorXd Coordinates::start() const {
  Eigen::VectorXd z(size());
  Eigen::Index o = 0;
  for (int i : index) z[o++] = base[i];
  return z;
}

ParamVector Coordinates::to_p(const Eigen::VectorXd& z) const {
  ParamVector p = base;
  Eigen::Index o = 0;
  for (int i : index) p[i] = z[o++];
  return p;
}

Eigen::MatrixXd Coordinates::jacobian() const {
  Eigen::MatrixXd t = Eigen::MatrixXd::Zero(kParams, size());
  Eigen::Index o = 0;
  for (int i : index) t(i, o++) = 1.0;
  return t;
}

namespace {

// One pass of a stage at p: a trial's also with `sums` (StageOptions::trial_covariance), whose
// validator it leaves in `validator`.
PassResult stage_pass(std::span<const WindowSample> window, const ParamVector& p,
                      const PassSettings& pass_settings, const TrialCovariance* sums,
                      Budget& budget, std::shared_ptr<ResidualValidator>& validator) {
  if (sums == nullptr) return budget.pass(window, p, pass_settings);
  PassSettings ps = pass_settings;
  ps.hac_bandwidth = sums->hac_bandwidth;
  ps.batches = sums->batches;
  validator = sums->validator(p);
  ps.validator = validator.get();
  return budget.pass(window, p, ps);
}

LmSettings lm_settings(std::size_t samples, const PassSettings& pass_settings, int max_iterations,
                       const StageOptions& options) {
  LmSettings lm;
  lm.max_iterations = max_iterations;
  lm.initial_damping = options.initial_damping;
  lm.decrement_tolerance = options.decrement_tolerance;
  lm.one_step_tolerance = options.one_step_tolerance;
  lm.observations = static_cast<double>(samples) *
                    ((pass_settings.weight[0] > 0.0 && !pass_settings.thermal_only ? 1.0 : 0.0) +
                     (pass_settings.weight[1] > 0.0 ? 1.0 : 0.0));
  return lm;
}

// Whether p is refused before its pass: the budget is spent (e.stop), or p is not finite or, for a
// joint model, not stable over the T̄ range already known (a failed step without simulating
// toward its overflow; its own pass only widens that range).
bool refused_before_pass(const ParamVector& p, bool thermal_only, const Budget& budget,
                         const TbarRange& range, Evaluation& e) {
  if (const StopReason stop = budget.stop(); stop != StopReason::none) {
    e.stop = to_text(stop);
    return true;
  }
  return !p.allFinite() || (!thermal_only && !stable_over(p, range));
}

// The one-step rule's check: the cost alone at p, which must be a model as stable as a trial's.
Evaluation cost_only(std::span<const WindowSample> window, const ParamVector& p,
                     PassSettings pass_settings, Budget& budget, const TbarRange& range) {
  Evaluation e;
  if (refused_before_pass(p, false, budget, range, e)) return e;
  pass_settings.jacobian = false;
  e.pass = budget.pass(window, p, pass_settings);
  e.finite = e.pass.finite && std::isfinite(e.pass.cost) && stable_over(p, widened(range, e.pass));
  e.cost = e.pass.cost;
  return e;
}

}  // namespace

StageResult run_stage(std::span<const WindowSample> window, const Coordinates& c,
                      const PassSettings& pass_settings, int max_iterations, Budget& budget,
                      const TbarRange& range, const StageOptions& options) {
  const double cost_floor = rounding_cost(
      window,
      {pass_settings.thermal_only ? 0.0 : pass_settings.weight[0], pass_settings.weight[1]});
  const Eigen::MatrixXd t = c.jacobian();
  const bool one_step = options.one_step_tolerance > 0.0 && options.trial_covariance != nullptr;
  const TrialCovariance* sums = options.trial_covariance;
  bool first = true;
  auto evaluate = [&](const Eigen::VectorXd& z) {
    Evaluation e;
    const bool start = std::exchange(first, false);
    // The start's pass carries the sums too where the one-step rule may end the stage there.
    const bool with_sums = !start || one_step;
    // p holds every entry of z: a non-finite step is a failed step, never a simulation.
    const ParamVector p = c.to_p(z);
    if (refused_before_pass(p, pass_settings.thermal_only, budget, range, e)) return e;
    if (start && !one_step && options.start_pass != nullptr) {
      e.pass = *options.start_pass;
    } else {
      e.pass =
          stage_pass(window, p, pass_settings, with_sums ? sums : nullptr, budget, e.validator);
    }
    if (start && sums != nullptr && !sums->serves_trials_from(e.pass)) sums = nullptr;
    // An unstable model (negative damping at some T̄ of the window, θ3 or θ5 ≤ 0) counts as not
    // finite: the solver backs off instead of following a diverging simulation.
    e.finite = e.pass.finite && std::isfinite(e.pass.cost) &&
               (pass_settings.thermal_only
                    ? p[kCooling] > 0.0 && extensions_physical_over(p, widened(range, e.pass))
                    : stable_over(p, widened(range, e.pass)));
    e.too_stiff = e.pass.too_stiff;
    if (e.finite && !pass_settings.thermal_only) {
      const TbarRange seen = widened(range, e.pass);
      e.unresolved = budget.unresolved(p, seen.lo, seen.hi);
    }
    e.cost = e.pass.cost;
    e.normal = t.transpose() * e.pass.jtwj * t;
    e.gradient = t.transpose() * e.pass.jtwr;
    return e;
  };
  auto cost_at = [&](const Eigen::VectorXd& z) {
    return cost_only(window, c.to_p(z), pass_settings, budget, range);
  };
  LmSettings lm = lm_settings(window.size(), pass_settings, max_iterations, options);
  lm.cost_floor = cost_floor;
  auto out = one_step ? levenberg_marquardt<Evaluation>(evaluate, c.start(), lm, cost_at)
                      : levenberg_marquardt<Evaluation>(evaluate, c.start(), lm);
  StageResult r;
  r.p = c.to_p(out.z);
  r.pass = std::move(out.at_z.pass);
  r.validator = std::move(out.at_z.validator);
  r.iterations = out.iterations;
  r.converged = out.converged;
  r.message = out.message;
  // The fit ends there: the stages after it would start from the same unresolved model.
  if (out.stalled) budget.end(StopReason::stalled);
  r.stopped = budget.stop() != StopReason::none;
  return r;
}

std::array<std::size_t, 2> parameters_per_channel(const FreeMask& free) {
  std::array<std::size_t, 2> count{};
  for (int i = 0; i < kParams; ++i) {
    if (!free[static_cast<std::size_t>(i)]) continue;
    if (in_x_output(i)) ++count[0];
    if (in_tbar_output(i)) ++count[1];
  }
  return count;
}

double variance_floor(std::span<const WindowSample> w, int channel) {
  double ss = 0.0;
  for (const WindowSample& s : w) ss += channel == 0 ? s.x * s.x : s.tbar * s.tbar;
  const double rms = std::sqrt(ss / static_cast<double>(w.size()));
  const double floor = 1e-15 * rms;
  return std::max(floor * floor, std::numeric_limits<double>::min());
}

}  // namespace scp::refine

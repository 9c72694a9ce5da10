#include "refine/scale_search.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <span>

#include "refine/golden_section.hpp"

namespace scp::refine {

namespace {

constexpr double kQuasiStatic = 30.0;

// The window's first kScaleSearchSeconds (at least 3 samples): several periods of the paper's
// fast sine pair, at a fraction of a long window's cost.
std::span<const WindowSample> search_prefix(std::span<const WindowSample> window) {
  std::size_t prefix = 3;
  while (prefix < window.size() && window[prefix].t - window.front().t <= kScaleSearchSeconds)
    ++prefix;
  return window.first(prefix);
}

// (b1): θ1, θ2, θ4 (θ3 held), x0, ẋ0 and, when estimated, the displacement's zero, on x at
// kQuasiStatic × the start's scale.
StopReason fit_ratios(FitContext& ctx, FitState& state, std::span<const WindowSample> head) {
  state.p.head<kMechanicalSize>() *= kQuasiStatic;
  FreeMask ratios{};
  for (const int i : {kDamping, kDampingSlope, kThermalForce, kX0, kXdot0}) ratios[i] = true;
  // A sensor's zero held at its start here is an offset of x that only a displacement from rest
  // can explain: x0 takes it, and the ratios that make it decay slowly enough are wrong (a 1 mm
  // zero at N3 stalled the fit at a fast pole). The warm refit does not come here.
  ratios[kXZeroSlot] = !ctx.settings.nuisance.x_zero.fixed;
  // The stiffness's softening is a ratio too (it scales with θ3, not with the inertia), and a
  // scale placed without it on data that need it runs away (the paper's model there is 99 % off).
  ratios[kStiffnessSofteningSlot] =
      ctx.settings.extensions.stiffness_softening != ExtensionMode::off;
  PassSettings ps;
  ps.weight = {1.0, 0.0};
  ps.extensions = ratios[kStiffnessSofteningSlot];
  const StageResult r = run_stage(head, Coordinates(ratios, state.p), ps,
                                  std::min(ctx.max_iterations, 50), ctx.budget, state.range);
  state.iterations += r.iterations;
  if (r.pass.finite) state.p = r.p;
  return r.stopped ? ctx.budget.stop() : StopReason::none;
}

// (b2): the scale s of θ1..θ4 by cost-only passes over ln s ∈ [−ln 900, 0]; then the start
// (`before`) instead if it fits better.
StopReason search_scale_factor(FitContext& ctx, FitState& state, std::span<const WindowSample> head,
                               const ParamVector& before) {
  Budget& budget = ctx.budget;
  ParamVector& p = state.p;
  const auto stopped = [&] { return budget.stop() != StopReason::none; };
  PassSettings ps;
  ps.weight = {1.0, 0.0};
  ps.jacobian = false;
  auto cost_at = [&](double ln_s) {
    ParamVector q = p;
    q.head<kMechanicalSize>() *= std::exp(ln_s);
    if (!q.allFinite() || stopped()) return std::numeric_limits<double>::infinity();
    const PassResult pr = budget.pass(head, q, ps);
    return pr.finite && stable_over(q, widened(state.range, pr))
               ? pr.cost
               : std::numeric_limits<double>::infinity();
  };
  const double ln2 = std::log(2.0);
  const double lo = -std::log(kQuasiStatic * kQuasiStatic);
  double best_ln = 0.0, best_cost = cost_at(0.0);
  // Both loops are bounded by their counts, not by floating-point comparisons alone.
  const int grid_points = static_cast<int>(std::floor(-lo / ln2 + 1e-9));
  for (int i = 1; i <= grid_points && !stopped(); ++i) {
    const double ln_s = -ln2 * i;
    const double cost = cost_at(ln_s);
    ++state.iterations;
    if (cost < best_cost) {
      best_cost = cost;
      best_ln = ln_s;
    }
  }
  // Golden section on [best − ln 2, best + ln 2] (clipped to the searched range).
  const GoldenResult golden =
      golden_section(std::max(lo, best_ln - ln2), std::min(0.0, best_ln + ln2), 0.05, 64, cost_at,
                     stopped, state.iterations);
  if (golden.cost < best_cost) best_ln = golden.x;
  p.head<kMechanicalSize>() *= std::exp(best_ln);
  // A start that already fits better is kept, first with its own initial state and zero (the
  // previous window's refined fit: the state the ratios were fitted with belongs to another scale
  // and makes it look worse, and the mechanical stage then creeps along the scale from the
  // search's tolerance), then with the ratios' state (an underdamped actuator whose quasi-static
  // ratios mislead).
  const double found = std::min(best_cost, golden.cost);
  for (const bool own_state : {true, false}) {
    if (stopped()) break;
    ParamVector q = p;
    q.head<kMechanicalSize>() = before.head<kMechanicalSize>();
    if (own_state) {
      for (const int i : {kX0, kXdot0, kXZeroSlot}) q[i] = before[i];
    }
    const PassResult at_start = budget.pass(head, q, ps);
    ++state.iterations;
    if (at_start.finite && stable_over(q, widened(state.range, at_start)) &&
        at_start.cost < found) {
      p = q;
      break;
    }
  }
  return budget.stop();
}

}  // namespace

StopReason search_scale(FitContext& ctx, FitState& state) {
  for (const int i : kMechanicalTheta)
    if (ctx.settings.known[static_cast<std::size_t>(i)]) return StopReason::none;
  const std::span<const WindowSample> head = search_prefix(ctx.window);
  const ParamVector before = state.p;
  if (const StopReason stop = fit_ratios(ctx, state, head); stop != StopReason::none) return stop;
  return search_scale_factor(ctx, state, head, before);
}

void start_with_positive_damping(const FitContext& ctx, FitState& state) {
  if (!ctx.settings.known[kDampingSlope] && !damped_over(state.p, state.range))
    state.p[kDampingSlope] = 0.0;
}

}  // namespace scp::refine

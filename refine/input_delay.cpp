#include "refine/input_delay.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "refine/delay_batch_means.hpp"
#include "refine/golden_section.hpp"
#include "refine/stages.hpp"

namespace scp::refine {

namespace {

// The delay's search has passes of its own: thermal-only, ~1/10 of a mechanical pass each.
constexpr int kDelayEvaluations = 2000;

// σ_d checked by batch means (refine/delay_batch_means.hpp): three thermal passes at the profile's
// (θ5, θ6, T̄0), weighted by T̄'s residual variance `var_t` there, with d at d̂ and d̂ ± σ_d (the
// profile is a parabola that far); d rides in θ1's slot, which the thermal passes leave fixed.
void check_delay(std::span<const WindowSample> window, const FreeMask& free,
                 InputDelayEstimate& out, double lowest, double var_t, Budget& budget,
                 const FitSettings& settings) {
  const double h = out.sigma;
  if (!(h > 0.0) || !(var_t > 0.0) || out.delay - h < lowest) return;
  PassSettings ps = thermal_pass_settings();
  ps.batches = settings.covariance_batches;
  ps.weight[1] = 1.0 / var_t;
  budget.set_input_delay(out.delay);
  const PassResult weighted = budget.pass(window, out.p, ps);
  budget.set_input_delay(out.delay - h);
  const PassResult below = budget.pass(window, out.p, ps);
  budget.set_input_delay(out.delay + h);
  const PassResult above = budget.pass(window, out.p, ps);
  budget.set_input_delay(out.delay);
  constexpr std::size_t kDelaySlot = kDamping;
  const BatchMeansCheck check =
      check_delay_against_batch_means(below, weighted, above, h, free, kDelaySlot);
  out.sigma_inflation = check.factor[kDelaySlot];
  out.sigma *= out.sigma_inflation;
}

}  // namespace

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

InputDelayEstimate estimate_input_delay(const FitContext& ctx, const ParamVector& start) {
  const std::span<const WindowSample> window = ctx.window;
  const double limit = ctx.settings.max_input_delay_s;
  FitSettings own = ctx.settings;
  own.max_evaluations = kDelayEvaluations;
  Budget budget(window, own);
  const FreeMask slots = thermal_slots(ctx.settings.known);
  Coordinates c(slots, start);
  const PassSettings ps = thermal_pass_settings();
  const double inf = std::numeric_limits<double>::infinity();
  InputDelayEstimate out;
  out.p = start;
  double best_cost = inf;
  // The thermal fit at d, started from the best one so far (a few iterations each).
  auto fit_at = [&](double d, ParamVector& p_at) {
    budget.set_input_delay(d);
    if (budget.stop() != StopReason::none) return inf;
    c.base = out.p;
    const StageResult r = run_stage(window, c, ps, ctx.max_iterations, budget);
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
  const auto stopped = [&] { return budget.stop() != StopReason::none; };
  // Golden section to 0.5 µs, then the vertex of the parabola the curvature is measured on: T̄
  // resolves d to a fraction of a µs on a clean link (tests/refine/test_fit.cpp,
  // AnUnmodelledOutputLatencyIsEstimatedFromTemperature).
  const double lowest = -earliest_switch_delay(window, limit);
  int steps = 0;
  golden_section(lowest, limit, 0.5e-6, 80, cost_at, stopped,
                 steps);  // cost_at keeps the best point it has seen
  if (!std::isfinite(best_cost) || stopped()) return out;
  double d = out.delay;
  // Curvature over ±h with h near σ_d itself (the parabola is exact there; far smaller steps
  // drown in the solver's tolerance), Δχ² = 1 at σ_d; a side beyond the search range is the
  // range's end.
  double h = std::min(1e-6, limit / 4);
  for (int round = 0; round < 8 && !stopped(); ++round) {
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
  if (out.ok && ctx.settings.covariance_batches > 1) {
    // best_cost is the weight-1 cost at (d̂, out.p): T̄'s residual variance, as σ_d's own.
    const double var_t = best_cost / dof(window.size(), c.index.size() + 1);
    check_delay(window, slots, out, lowest, var_t, budget, ctx.settings);
  }
  return out;
}

StopReason fit_input_delay(FitContext& ctx, FitState& state) {
  const FitSettings& settings = ctx.settings;
  if (!(settings.max_input_delay_s > 0.0)) return StopReason::none;
  const InputDelayEstimate estimate = estimate_input_delay(ctx, state.p);
  if (settings.cancel != nullptr && settings.cancel->load(std::memory_order_relaxed))
    return StopReason::cancelled;
  if (!estimate.ok) return StopReason::input_delay_not_estimated;
  state.p = estimate.p;
  ctx.budget.set_input_delay(estimate.delay);
  state.delay = estimate;
  return StopReason::none;
}

}  // namespace scp::refine

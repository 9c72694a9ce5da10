#include "refine/input_delay.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

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
  PassSettings ps = thermal_pass_settings(settings);
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

double latest_switch_delay(std::span<const WindowSample> w, double limit) {
  if (w.size() < 2) return limit;
  std::vector<double> room(w.size() - 1);
  for (std::size_t k = 1; k < w.size(); ++k)
    room[k - 1] = w[k].t - std::max(w[k].voltage_since, w[k - 1].t);
  const auto mid = room.begin() + static_cast<std::ptrdiff_t>(room.size() / 2);
  std::nth_element(room.begin(), mid, room.end());
  return std::min(limit, *mid);
}

namespace {

// The thermal cost profiled along d: at each d, (θ5, θ6, T̄0) refitted from the best fit so far (a
// few iterations each); the best point seen is kept in `best`.
class DelayProfile {
 public:
  DelayProfile(const FitContext& ctx, const ParamVector& start)
      : ctx_(ctx),
        budget_(ctx.window, own_settings(ctx.settings)),
        slots_(thermal_slots(ctx.settings)),
        coordinates_(slots_, start) {
    best.p = start;
  }

  bool stopped() const { return budget_.stop() != StopReason::none; }

  // The thermal fit's cost at d (∞ where it cannot be simulated); `p_at` its solution.
  double fit_at(double d, ParamVector& p_at) {
    budget_.set_input_delay(d);
    if (stopped()) return kInfinity;
    coordinates_.base = best.p;
    const StageResult r = run_stage(ctx_.window, coordinates_, thermal_pass_settings(ctx_.settings),
                                    ctx_.max_iterations, budget_);
    p_at = r.p;
    return r.pass.finite ? r.pass.cost : kInfinity;
  }

  // fit_at, keeping the best point seen.
  double cost_at(double d) {
    ParamVector p_at = best.p;
    const double cost = fit_at(d, p_at);
    if (cost < best_cost) {
      best_cost = cost;
      best.delay = d;
      best.p = p_at;
    }
    return cost;
  }

  // T̄'s residual variance at the best point (the cost has weight 1).
  double residual_variance() const {
    return best_cost / dof(ctx_.window.size(), coordinates_.index.size() + 1);
  }

  Budget& budget() { return budget_; }
  const FreeMask& slots() const { return slots_; }

  static constexpr double kInfinity = std::numeric_limits<double>::infinity();
  InputDelayEstimate best;
  double best_cost = kInfinity;

 private:
  static FitSettings own_settings(FitSettings s) {
    s.max_evaluations = kDelayEvaluations;
    return s;
  }

  const FitContext& ctx_;
  Budget budget_;
  FreeMask slots_;
  Coordinates coordinates_;
};

// σ_d from the profile's curvature over ±h, Δχ² = 1, with h near σ_d itself (the parabola is
// exact there; far smaller steps drown in the solver's tolerance); a side beyond the search range
// [lowest, limit] is the range's end. Each round d̂ moves to the parabola's vertex where that
// lowers the cost: the golden section stops at its 0.5 µs tolerance, and where the noise lets
// T̄ resolve d far more finely (a clean link: σ_d of 0.1 ns) the rest of the way is the
// vertex's. Settled once σ_d and h agree and the vertex lay within h.
void measure_curvature(DelayProfile& profile, double lowest, double limit) {
  InputDelayEstimate& out = profile.best;
  double d = out.delay;
  double h = std::min(1e-6, limit / 4);
  for (int round = 0; round < 8 && !profile.stopped(); ++round) {
    const double c0 = profile.best_cost;
    const double var_t = profile.residual_variance();
    const double lo = std::max(lowest, d - h), hi = std::min(limit, d + h);
    const double cm = lo < d ? profile.cost_at(lo) : c0, cp = hi > d ? profile.cost_at(hi) : c0;
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
    // A side point that lowered the cost is already d̂ (cost_at keeps the best); the vertex is
    // tried within a few h of where the parabola was measured.
    const double vertex = std::clamp(0.5 * (lo + hi) - 0.5 * (sl + sr) / curvature,
                                     std::max(lowest, d - 4.0 * h), std::min(limit, d + 4.0 * h));
    const double moved = std::abs(vertex - d);
    if (moved > 0.0) {
      ParamVector p_at = out.p;
      const double cv = profile.fit_at(vertex, p_at);
      if (cv <= profile.best_cost) {
        profile.best_cost = cv;
        out.delay = vertex;
        out.p = p_at;
      }
    }
    const bool settled = out.sigma < 4.0 * h && out.sigma > 0.25 * h && moved <= h;
    if (settled) break;
    h = std::clamp(out.sigma, 1e-9, limit / 4);
    d = out.delay;
  }
}

}  // namespace

InputDelayEstimate estimate_input_delay(const FitContext& ctx, const ParamVector& start) {
  const double limit = ctx.settings.max_input_delay_s;
  DelayProfile profile(ctx, start);
  // Golden section to 0.5 µs, then the vertex of the parabola the curvature is measured on: T̄
  // resolves d to a fraction of a µs on a clean link (tests/refine/test_fit.cpp,
  // AnUnmodelledOutputLatencyIsEstimatedFromTemperature).
  const double lowest = -earliest_switch_delay(ctx.window, limit);
  const double highest = latest_switch_delay(ctx.window, limit);
  int steps = 0;
  golden_section(
      lowest, highest, 0.5e-6, 80, [&](double d) { return profile.cost_at(d); },
      [&] { return profile.stopped(); }, steps);  // cost_at keeps the best point it has seen
  if (!std::isfinite(profile.best_cost) || profile.stopped()) return profile.best;
  measure_curvature(profile, lowest, highest);
  InputDelayEstimate& out = profile.best;
  out.at_limit = std::abs(out.delay) > limit * (1.0 - 1e-6);
  if (out.ok && ctx.settings.covariance_batches > 1) {
    // best_cost is the weight-1 cost at (d̂, out.p): T̄'s residual variance, as σ_d's own.
    check_delay(ctx.window, profile.slots(), out, lowest, profile.residual_variance(),
                profile.budget(), ctx.settings);
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

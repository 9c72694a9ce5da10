// The sure detector's alarm held until a window lies after its onset: a step, or a drift that
// started late?
//
// Against the trend it departed from (frozen at the alarm), a window of length L ending at t
// departs by, for a step ∆ at s and a drift of rate r from s (u = t − s),
//   step:  ∆·min(max(u, 0), L)/L          (the share of the window after s)
//   drift: r·u²/(2L) for 0 ≤ u ≤ L, r·(u − L/2) after
// Both are fitted to the named parameter's deviation ("alone", wald.hpp) in the windows from one
// window length before the alarm's onset to now, over a grid of s; the smaller residual sum
// decides. The windows' errors are correlated, so the sums are not compared by a significance
// test, only by size: the shapes differ most where the evidence is, at the onset.
#include <algorithm>
#include <cmath>
#include <vector>

#include "health/monitor.hpp"

namespace scp::health {

namespace {

constexpr double kOnsetGridSeconds = 5.0;

struct Deviation {
  double t_end, value;
};

struct WindowShapeFit {
  double sse = 1e300, onset = 0.0, amplitude = 0.0;
};

double shape(bool step, double u, double length) {
  if (u <= 0.0) return 0.0;
  if (step) return std::min(u, length) / length;
  return u <= length ? u * u / (2.0 * length) : u - 0.5 * length;
}

WindowShapeFit fit_shape(bool step, const std::vector<Deviation>& d, double length, double first,
                         double last) {
  WindowShapeFit best;
  double total = 0.0;
  for (const auto& x : d) total += x.value * x.value;
  for (double s = first; s <= last; s += kOnsetGridSeconds) {
    double gg = 0.0, gd = 0.0;
    for (const auto& x : d) {
      const double g = shape(step, x.t_end - s, length);
      gg += g * g;
      gd += g * x.value;
    }
    if (!(gg > 0.0)) continue;
    const double sse = total - gd * gd / gg;
    if (sse < best.sse) best = {sse, s, gd / gg};
  }
  return best;
}

}  // namespace

void HealthMonitor::confirm_pending(const WindowEstimate& w) {
  const ChangePoint candidate = pending_.change;
  const int i = candidate.parameter;
  const TrendFit& ref = pending_.reference;
  const double length = w.length();
  std::vector<Deviation> d;
  for (const auto& h : history_) {
    if (h.t_end < candidate.onset - length) continue;
    const Vector6 expected = ref.level + ref.slope * (h.midpoint() - ref.t_eval);
    const WaldResult r =
        wald_test(h.theta, h.covariance, expected, pending_.reference_covariance, {});
    d.push_back({h.t_end, r.parameters[i].alone});
  }
  pending_.active = false;
  const double first = candidate.onset - length, last = w.t_end - 0.5 * length;
  const WindowShapeFit step = fit_shape(true, d, length, first, last);
  WindowShapeFit drift = fit_shape(false, d, length, first, last);
  ShapeFit ramp;
  const bool blocks_drift = blocks_show_drift(i, candidate.onset, ramp);
  if (blocks_drift) drift = {0.0, ramp.onset, ramp.slope};
  if (!blocks_drift && step.sse <= drift.sse) {
    ChangePoint c = candidate;
    c.onset = step.onset;
    c.detected_at = w.t_end;
    stop_naming();
    raise_change(c);
    return;
  }
  std::array<ParameterTrend, kParams> trend{};
  ParameterTrend& p = trend[i];
  p.tested = true;
  p.per_hour = drift.amplitude * 3600.0;
  p.relative_per_hour = ref.level[i] != 0.0 ? p.per_hour / std::abs(ref.level[i]) : 0.0;
  p.drifting = true;
  if (drift_armed_) raise_drift(w.t_end, trend, drift.onset, i);
  // The trends start again where the drift began, so that the reference follows it.
  start_segment(drift.onset, w.t_end);
}

}  // namespace scp::health

// The health monitor's naming of a fast alarm's change: at the alarm from the residuals since the
// onset, and, where they do not yet separate the candidates, from every block after it against
// the reference the change departed from, until they do (an event `named`) or a window after the
// onset gives the new reference; then from the refined windows after the onset that share no
// data, until one does or the reference span has passed (the change then stays named as its set
// of candidates).
#include <algorithm>
#include <cmath>
#include <span>

#include "health/monitor.hpp"

namespace scp::health {

// The onset is the start of the block in which the change is found to begin (a CUSUM's change
// point, a step fit's onset): the naming starts with the block after it. Every sample from it on
// then lies after the change, where the residual is the change's response alone up to a free
// response from the change's moment, which the nuisance columns absorb; a sample before it
// would not be, and over the seconds after a fast alarm it decides the name.
double HealthMonitor::naming_start(double onset) const {
  return onset + 0.5 * settings_.block_s;
}

NamingSettings HealthMonitor::naming_settings() const {
  return {kNameMargin, settings_.min_relative_change};
}

// The change as the fast detector reports it: every parameter's shift alone with σ from the
// profiled sums after the onset (from `plain`, the sums since the onset, where those have no data
// yet: an alarm in the block after the change's), and the name when it is definite.
ChangePoint HealthMonitor::fast_change(const ChangeEvidence& since, const ScoreBlock& plain,
                                       double onset, double t) const {
  const Naming& name = since.name;
  ChangePoint c;
  c.detector = Detector::fast;
  c.onset = onset;
  c.detected_at = t;
  c.definite = name.definite;
  c.parameter = name.definite ? name.best.parameter : -1;
  c.candidates = name.candidates;
  const Vector6 ref = reference_at(onset).theta;
  for (int i = 0; i < kParams; ++i) {
    const ProfiledSum& output = since.outputs[static_cast<std::size_t>(block_of(i))];
    const bool profiled = output.information(i, i) > 0.0;
    const double info = profiled ? output.information(i, i) : plain.information(i, i);
    const double score = profiled ? output.score[i] : plain.score[i];
    if (name.best.parameter < 0) c.candidates[i] = info > 0.0;
    ParameterShift& p = c.parameters[i];
    p.tested = info > 0.0;
    if (!p.tested) continue;
    p.delta = score / info;
    p.sigma = 1.0 / std::sqrt(info);
    p.z = p.delta / p.sigma;
    p.relative = ref[i] != 0.0 ? p.delta / std::abs(ref[i]) : 0.0;
    p.moved = i == c.parameter;
  }
  return c;
}

void HealthMonitor::name_block(const ScoreBlock& block) {
  naming_.blocks.push_back(block);
  const ChangeEvidence since =
      weigh_change(naming_.blocks, naming_start(naming_.change.onset),
                   reference_at(naming_.change.onset).theta, naming_settings());
  if (!since.name.definite) return;
  raise_name(fast_change(since, ScoreBlock{}, naming_.change.onset, block.t_end));
}

// The reference the change departed from at a window's midpoint: the trend of the windows that
// ended before the onset refitted there (its extrapolation's σ grows with the distance), or the
// one frozen at the alarm when there were none (the baseline).
TrendFit HealthMonitor::reference_for_naming(const WindowEstimate& w) const {
  const std::vector<WindowEstimate>& before = naming_.windows_before;
  if (before.empty()) {
    TrendFit ref = naming_.reference;
    if (ref.with_slope) ref.level += ref.slope * (w.midpoint() - ref.t_eval);
    return ref;
  }
  return fit_trend(before, w.midpoint(), spans_a_slope(before));
}

namespace {

// The mean of windows that share no data: θ̄ with covariance ΣC/n², at their mean midpoint.
WindowEstimate mean_of(std::span<const WindowEstimate> windows) {
  WindowEstimate m;
  for (const auto& w : windows) {
    m.t_begin += w.t_begin;
    m.t_end += w.t_end;
    m.theta += w.theta;
    m.covariance += w.covariance;
  }
  const auto n = static_cast<double>(windows.size());
  m.t_begin /= n;
  m.t_end /= n;
  m.theta /= n;
  m.covariance /= n * n;
  return m;
}

}  // namespace

// The windows after the onset that share no data, pooled, against the reference the change
// departed from (both covariances): among the candidates, the parameter whose change alone
// explains their departure best (wald.hpp's GLR), when it beats the runner-up by the margin the
// residuals' naming asks (naming.hpp: what that parameter leaves unexplained of the block's χ²
// beyond its degrees of freedom widens it). A drifting plant's window is a misfit whose
// departure no one parameter explains, and a runner-up close behind is then no evidence
// against it. Otherwise the next window that shares no data with these joins them, until the
// reference span has passed since the onset; the change then stays named as its set. Pooled,
// not tried one by one: each try of a misfit's window would be another chance for its scatter
// to look like one parameter (a1/m named for a b/m drift at the second or third window). A
// window whose fit the validation found a misfit in a candidate's block (a plant drifting
// within it) neither names nor joins.
void HealthMonitor::name_from_window(const WindowEstimate& window) {
  naming_.active = false;
  naming_.next_window_from = window.t_end;
  if (window.t_end - naming_.change.onset > settings_.reference_span_s) naming_.by_windows = false;
  for (int i = 0; i < kParams; ++i)
    if (naming_.change.candidates[i] && window.misfit[static_cast<std::size_t>(block_of(i))])
      return;
  naming_.windows_after.push_back(window);
  const WindowEstimate w = mean_of(naming_.windows_after);
  const TrendFit ref = reference_for_naming(w);
  const Vector6& expected = ref.level;
  const WaldResult r = wald_test(w.theta, w.covariance, expected, ref.level_covariance, {});
  int best = -1, second = -1;
  for (int i = 0; i < kParams; ++i) {
    if (!naming_.change.candidates[i] || !r.parameters[i].tested) continue;
    const double g = r.parameters[i].glr;
    if (best < 0 || g > r.parameters[best].glr) {
      second = best;
      best = i;
    } else if (second < 0 || g > r.parameters[second].glr) {
      second = i;
    }
  }
  if (best < 0) return;
  const double gap = r.parameters[best].glr - (second >= 0 ? r.parameters[second].glr : 0.0);
  const BlockWald& block = r.blocks[static_cast<std::size_t>(block_of(best))];
  const double unexplained = block.statistic - r.parameters[best].glr - (block.dof - 1);
  const double relative =
      expected[best] != 0.0 ? r.parameters[best].alone / std::abs(expected[best]) : 0.0;
  if (!(gap >= needed_gap(unexplained, kNameMargin)) ||
      !(std::abs(relative) >= settings_.min_relative_change))
    return;
  ChangePoint c = naming_.change;
  c.detector = Detector::sure;
  c.detected_at = window.t_end;
  c.parameter = best;
  c.definite = true;
  c.parameters = r.parameters;
  for (int i = 0; i < kParams; ++i) {
    ParameterShift& p = c.parameters[i];
    if (i == best) {
      // The change alone, as the fast detector's single-parameter GLR reports it.
      p.delta = p.alone;
      p.sigma = p.alone_sigma;
      p.z = p.sigma > 0.0 ? p.delta / p.sigma : 0.0;
      p.relative = expected[i] != 0.0 ? p.delta / std::abs(expected[i]) : 0.0;
    }
    p.moved = i == best;
  }
  raise_name(c);
}

void HealthMonitor::stop_naming() noexcept {
  naming_.active = false;
  naming_.by_windows = false;
}

void HealthMonitor::raise_name(const ChangePoint& change) {
  stop_naming();
  report_.change = change;
  name_in_chain(change);
  push_change_event(EventKind::named, change);
  update_reference(change.detected_at);
}

}  // namespace scp::health

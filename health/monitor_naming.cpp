// The health monitor's naming of a fast alarm's change: at the alarm from the residuals since the
// onset, and, where they do not yet separate the candidates, from every block after it against
// the reference the change departed from, until they do (an event `named`) or a window after the
// onset gives the new reference (the change then stays named as its set of candidates).
#include <algorithm>
#include <cmath>

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

// The first window after the onset against the reference the change departed from (both
// covariances): among the candidates, the parameter whose change alone explains the window's
// departure best (wald.hpp's GLR), when it beats the runner-up by the margin. Otherwise the
// change stays named as its set.
void HealthMonitor::name_from_window(const WindowEstimate& w) {
  const TrendFit& ref = naming_.reference;
  Vector6 expected = ref.level;
  if (ref.with_slope) expected += ref.slope * (w.midpoint() - ref.t_eval);
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
  naming_.active = false;
  if (best < 0) return;
  const double gap = r.parameters[best].glr - (second >= 0 ? r.parameters[second].glr : 0.0);
  const double relative =
      expected[best] != 0.0 ? r.parameters[best].alone / std::abs(expected[best]) : 0.0;
  if (!(gap >= kNameMargin) || !(std::abs(relative) >= settings_.min_relative_change)) return;
  ChangePoint c = naming_.change;
  c.detector = Detector::sure;
  c.detected_at = w.t_end;
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

void HealthMonitor::raise_name(const ChangePoint& change) {
  naming_.active = false;
  report_.change = change;
  name_in_chain(change);
  push_change_event(EventKind::named, change);
  update_reference(change.detected_at);
}

}  // namespace scp::health

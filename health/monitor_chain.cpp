// Changes that recur in the same parameters are a drift.
//
// After a change the detectors restart from the first window that lies wholly after its onset,
// which describes the actuator as it has become. After a step that reference stays right, and
// the detectors alarm again only at their designed false-alarm rate (a third each of one in
// false_alarm_days). A plant that keeps moving makes each new reference stale within minutes: it
// alarms again soon after every restart, and each alarm is the same drift seen once more, not a
// new step. So an alarm that may be one of the parameters the latest change may be (its name, or
// its candidates while it has none, and every name given since), within reference_span_s of the
// last such alarm, continues it: the first raises one `drift` (the slopes of every window since
// the first onset), the next are counted (`drift_alarms`) and restart the detectors without an
// event, until the alarms stop for reference_span_s. Two real steps of those parameters within
// that span are reported as one drift; the false alarms the rule can turn into a drift are the
// fast and sure detectors' designed rate times reference_span_s. A drift of the mechanical
// block is named when the trends of θ's scale-free ratios single out one parameter
// (drift_naming.hpp).
#include <cmath>
#include <vector>

#include "health/drift_naming.hpp"
#include "health/monitor.hpp"
#include "health/naming.hpp"

namespace scp::health {

namespace {

// The parameters a change may be: the one named, else its candidates (all when it has none).
ParameterMask parameters_of(const ChangePoint& c) {
  ParameterMask mask{};
  if (c.parameter >= 0) {
    mask[static_cast<std::size_t>(c.parameter)] = true;
    return mask;
  }
  bool any = false;
  for (bool b : c.candidates) any = any || b;
  if (any) return c.candidates;
  mask.fill(true);
  return mask;
}

bool overlap(const ParameterMask& a, const ParameterMask& b) {
  for (int i = 0; i < kParams; ++i)
    if (a[i] && b[i]) return true;
  return false;
}

bool within_mechanical_block(const ParameterMask& m) {
  for (int i = kBlockFirst[1]; i < kBlockEnd[1]; ++i)
    if (m[i]) return false;
  return true;
}

}  // namespace

void HealthMonitor::start_chain(const ChangePoint& change) {
  chain_.active = true;
  chain_.parameters = parameters_of(change);
  chain_.first_onset = change.onset;
  chain_.last_detected = change.detected_at;
  chain_.drift_raised = false;
}

// Whether `change` continues the latest one; if so it is taken as such (the first raises the
// drift) and the detectors restart after it.
bool HealthMonitor::absorbed_by_chain(const ChangePoint& change) {
  if (!chain_.active || change.detected_at - chain_.last_detected > settings_.reference_span_s ||
      !overlap(chain_.parameters, parameters_of(change)))
    return false;
  chain_.last_detected = change.detected_at;
  chain_.add(parameters_of(change));
  ++report_.drift_alarms;
  stop_naming();  // the change it began with is a drift now, not a step to name
  if (!chain_.drift_raised) {
    chain_.drift_raised = true;
    std::vector<WindowEstimate> since;
    for (const auto& w : all_windows_)
      if (w.t_begin >= chain_.first_onset) since.push_back(w);
    const DriftReport trend = since.empty() ? DriftReport{} : assess_trend(since, since.back());
    std::array<ParameterTrend, kParams> rates = trend.parameters;
    DriftName name;
    if (within_mechanical_block(chain_.parameters))
      name = name_mechanical_drift(since, std::sqrt(kNameMargin));
    if (name.parameter >= 0 && !chain_.parameters[static_cast<std::size_t>(name.parameter)])
      name = {};
    if (name.parameter >= 0) rates[static_cast<std::size_t>(name.parameter)] = name.trend;
    set_state(State::drift, change.detected_at);
    raise_drift(change.detected_at, rates, chain_.first_onset, name.parameter, chain_.parameters);
  }
  start_segment(change.onset, change.detected_at);
  return true;
}

// A name given to the latest change later (an event `named`) is one more parameter it may be.
void HealthMonitor::name_in_chain(const ChangePoint& change) {
  if (chain_.active) chain_.add(parameters_of(change));
}

}  // namespace scp::health

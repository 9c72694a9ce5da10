// The health monitor's windows: the baseline deviation, the sure detector against the trend
// reference, the drift test and the state machine. The fast detector's blocks are in
// monitor_fast.cpp.
#include "health/monitor.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>

#include "health/scan_threshold.hpp"

namespace scp::health {

namespace {

constexpr double kSecondsPerDay = 86400.0;
// Three detectors share the false-alarm budget: fast, sure and drift.
constexpr double kDetectors = 3.0;
// Within a significant block, parameters beyond this many σ are named (wald.hpp).
constexpr double kNameZ = 2.0;
// The trend the sure detector tests against must span this many window lengths of data.
constexpr double kSureMinSpanWindows = 3.0;

bool usable(const WindowEstimate& w) {
  return std::isfinite(w.t_begin) && std::isfinite(w.t_end) && w.t_end > w.t_begin &&
         w.theta.allFinite() && w.covariance.allFinite() &&
         (w.covariance.diagonal().array() >= 0.0).all();
}

// tr(C_d⁻¹ C_w)/p over the block's free parameters: the share of the tested difference's
// variance that the moving window renews (β·L of scan_threshold.hpp).
double renewed_share(int block, const Matrix6& c_window, const Matrix6& c_reference, int& dof) {
  int idx[kParams], m = 0;
  for (int i = kBlockFirst[block]; i < kBlockEnd[block]; ++i)
    if (c_window(i, i) > 0.0 || c_reference(i, i) > 0.0) idx[m++] = i;
  dof = m;
  if (m == 0) return 0.0;
  Eigen::MatrixXd cd(m, m), cw(m, m);
  for (int i = 0; i < m; ++i)
    for (int j = 0; j < m; ++j) {
      cw(i, j) = c_window(idx[i], idx[j]);
      cd(i, j) = cw(i, j) + c_reference(idx[i], idx[j]);
    }
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(cd);
  if (ldlt.info() != Eigen::Success) return 1.0;
  const double share = ldlt.solve(cw).trace() / m;
  return std::isfinite(share) ? std::clamp(share, 1e-6, 1.0) : 1.0;
}

}  // namespace

const char* state_name(State state) noexcept {
  switch (state) {
    case State::drift:
      return "drift";
    case State::changed:
      return "changed";
    case State::ok:
      break;
  }
  return "ok";
}

const char* detector_name(Detector detector) noexcept {
  switch (detector) {
    case Detector::fast:
      return "fast";
    case Detector::sure:
      return "sure";
    case Detector::none:
      break;
  }
  return "none";
}

const char* event_name(EventKind kind) noexcept {
  switch (kind) {
    case EventKind::drift:
      return "drift";
    case EventKind::acknowledged:
      return "acknowledged";
    case EventKind::named:
      return "named";
    case EventKind::changed:
      break;
  }
  return "changed";
}

HealthMonitor::HealthMonitor(const HealthSettings& settings, const WindowEstimate& baseline)
    : settings_(settings),
      baseline_(baseline),
      rate_per_detector_(1.0 / (kDetectors * settings.false_alarm_days * kSecondsPerDay)),
      segment_start_(-std::numeric_limits<double>::infinity()),
      last_window_end_(-std::numeric_limits<double>::infinity()),
      accumulator_(settings.block_s) {
  report_.baseline_indicators =
      derive_indicators(baseline.theta, baseline.covariance, settings.heat_capacity_j_per_c);
  // The fast detector waits for a live window: against the baseline alone it cannot tell a
  // plant that drifts from one that has stepped (docs/health.md).
  reference_.theta = baseline.theta;
  reference_.covariance = baseline.covariance;
  // The baseline's times may be from another run (a file made elsewhere): the state's clock
  // starts with this monitor.
  report_.since = 0.0;
}

// Whether the windows' midpoints span enough for a trend to fit a slope (trend_min_span_s).
bool HealthMonitor::spans_a_slope(std::span<const WindowEstimate> windows) const {
  return !windows.empty() && windows.back().midpoint() - windows.front().midpoint() >=
                                 std::max(settings_.trend_min_span_s, 1e-9);
}

HealthMonitor::Prediction HealthMonitor::predict(double t, double data_before) const {
  std::vector<WindowEstimate> before;
  const double oldest = data_before - settings_.reference_span_s;
  for (const auto& w : history_)
    if (w.t_end <= data_before && w.t_begin >= oldest) before.push_back(w);
  Prediction p;
  if (before.empty()) {
    // Only the first window of all is tested against the baseline (a change while nothing ran);
    // after it, a window is tested only against live windows that share none of its data.
    if (!first_segment_ || tested_against_baseline_) return p;
    p.valid = true;
    p.fit.valid = true;
    p.fit.windows = 1;
    p.fit.t_eval = t;
    p.fit.level = baseline_.theta;
    p.fit.level_covariance = baseline_.covariance;
    p.from_baseline = true;
    return p;
  }
  p.fit = fit_trend(before, t, spans_a_slope(before));
  p.valid = p.fit.valid;
  return p;
}

double HealthMonitor::sure_block_threshold(int block, const WindowEstimate& w,
                                           const Matrix6& c_ref) const {
  int dof = 0;
  const double share = renewed_share(block, w.covariance, c_ref, dof);
  if (dof == 0) return 0.0;
  const double length = w.length();
  const double spacing =
      have_last_test_ ? std::clamp(w.t_end - last_test_end_, 1e-3, length) : length;
  return chi_square_scan_threshold(rate_per_detector_ / kBlocks, dof, share / length, spacing);
}

void HealthMonitor::add_window(const WindowEstimate& w) {
  ++report_.windows;
  if (!usable(w) || w.t_end <= last_window_end_) {
    ++report_.windows_rejected;
    return;
  }
  last_window_end_ = w.t_end;
  all_windows_.push_back(w);
  const double oldest_kept = w.t_end - settings_.trend_span_s;
  std::erase_if(all_windows_,
                [oldest_kept](const WindowEstimate& h) { return h.t_begin < oldest_kept; });
  report_.has_window = true;
  report_.indicators = derive_indicators(w.theta, w.covariance, settings_.heat_capacity_j_per_c);
  WaldThresholds baseline_th;
  for (int b = 0; b < kBlocks; ++b)
    baseline_th.block[b] = sure_block_threshold(b, w, baseline_.covariance);
  baseline_th.name_z = kNameZ;
  baseline_th.min_relative_change = settings_.min_relative_change;
  report_.baseline_deviation =
      wald_test(w.theta, w.covariance, baseline_.theta, baseline_.covariance, baseline_th);
  if (naming_.by_windows && w.t_begin >= naming_.next_window_from) name_from_window(w);
  if (w.t_begin >= segment_start_) test_against_reference(w);
  tested_against_baseline_ = true;
  // A window that straddles a change (the one just found or an earlier one) leaves the trends.
  if (w.t_begin >= segment_start_) {
    history_.push_back(w);
    const double oldest = w.t_end - settings_.trend_span_s;
    std::erase_if(history_, [oldest](const WindowEstimate& h) { return h.t_begin < oldest; });
    if (pending_.active && w.t_begin >= pending_.change.onset) confirm_pending(w);
    if (w.t_begin >= segment_start_) update_drift(w);
  }
  last_window_length_ = w.length();
  update_reference(w.t_end);
  design_cusums();
}

void HealthMonitor::test_against_reference(const WindowEstimate& w) {
  if (pending_.active) return;
  const Prediction p = predict(w.midpoint(), w.t_begin);
  report_.reference_tested = p.valid;
  if (!p.valid) return;
  WaldThresholds th;
  for (int b = 0; b < kBlocks; ++b)
    th.block[b] = sure_block_threshold(b, w, p.fit.level_covariance);
  th.name_z = kNameZ;
  th.min_relative_change = settings_.min_relative_change;
  const WaldResult r = wald_test(w.theta, w.covariance, p.fit.level, p.fit.level_covariance, th);
  report_.reference_deviation = r;
  // A level without a slope cannot tell a drift from a step: only the baseline (the first
  // window, a change while nothing ran) or a trend with its slope may raise `changed`. And a
  // short trend's extrapolation moves with each new window (its newest windows weigh most), so
  // its tests renew faster than the window's β says: on simulated steady plants the rate
  // matched the design only once the trend spanned kSureMinSpanWindows (docs/health.md).
  const bool may_alarm =
      (p.fit.with_slope && p.fit.data_span >= kSureMinSpanWindows * w.length()) || p.from_baseline;
  if (may_alarm && r.alarm()) {
    ChangePoint c;
    c.detector = Detector::sure;
    c.detected_at = w.t_end;
    c.parameter = r.first_named();
    c.parameters = r.parameters;
    c.onset = window_onset_estimate(w, c.parameter, r.parameters[c.parameter].delta);
    if (p.from_baseline) {
      stop_naming();
      raise_change(c);  // a change while nothing ran: nothing to tell it from a drift
      return;
    }
    // A step or a drift that started late? Decided once a window lies after the onset
    // (monitor_confirm.cpp).
    pending_.active = true;
    pending_.change = c;
    pending_.reference = p.fit;
    pending_.reference_covariance = p.fit.level_covariance;
    return;
  }
  have_last_test_ = true;
  last_test_end_ = w.t_end;
  for (int i = 0; i < kParams; ++i) last_test_delta_[i] = r.parameters[i].delta;
}

// A step ∆ at τ inside a window [t_end − L, t_end] moves its θ̂ by ∆·(t_end − τ)/L: linear in
// t_end, zero at τ. Two consecutive tests give τ. (Not a CUSUM's change point: a step the fast
// detector sees has raised its alarm long before a window, and a CUSUM on the innovations that
// stands above zero without alarming is as likely a chance excursion as a start; under a drift
// that started late such an onset tipped the shape test to a step.)
double HealthMonitor::window_onset_estimate(const WindowEstimate& w, int parameter,
                                            double delta) const {
  if (!have_last_test_) return w.t_begin;
  const double previous = last_test_delta_[parameter];
  const double step = delta - previous;
  if (!(delta * step > 0.0)) return last_test_end_;
  const double onset = w.t_end - delta * (w.t_end - last_test_end_) / step;
  return std::clamp(onset, w.t_begin, w.t_end);
}

// The drift test on `windows` (time order, `latest` the newest): each parameter's slope against
// the scan threshold and drift_per_hour. Not valid below two windows whose midpoints span
// trend_min_span_s.
DriftReport HealthMonitor::assess_trend(std::span<const WindowEstimate> windows,
                                        const WindowEstimate& latest) const {
  DriftReport d;
  if (windows.size() < 2 || !spans_a_slope(windows)) return d;
  const TrendFit fit = fit_trend(windows, latest.midpoint(), true);
  if (!fit.with_slope) return d;
  int free = 0;
  for (int i = 0; i < kParams; ++i) free += fit.slope_sigma[i] > 0.0 ? 1 : 0;
  if (free == 0) return d;
  d.valid = true;
  d.data_span_s = fit.data_span;
  d.windows = fit.windows;
  // A moving least-squares slope over a span S decorrelates at β = 3/S (scan_threshold.hpp).
  const double span = std::max(fit.data_span, latest.length());
  const double spacing = std::clamp(latest.t_end - windows[windows.size() - 2].t_end, 1e-3, span);
  d.z_threshold =
      std::sqrt(chi_square_scan_threshold(rate_per_detector_ / free, 1, 3.0 / span, spacing));
  for (int i = 0; i < kParams; ++i) {
    ParameterTrend& p = d.parameters[i];
    if (!(fit.slope_sigma[i] > 0.0)) continue;
    p.tested = true;
    p.per_hour = fit.slope[i] * 3600.0;
    p.sigma_per_hour = fit.slope_sigma[i] * 3600.0;
    p.relative_per_hour = fit.level[i] != 0.0 ? p.per_hour / std::abs(fit.level[i]) : 0.0;
    p.drifting = std::abs(fit.slope[i]) > d.z_threshold * fit.slope_sigma[i] &&
                 std::abs(p.relative_per_hour) >= settings_.drift_per_hour;
  }
  return d;
}

void HealthMonitor::update_drift(const WindowEstimate& w) {
  report_.drift = assess_trend(history_, w);
  const DriftReport& d = report_.drift;
  if (!d.valid) return;
  bool drifting = false;
  for (const auto& p : d.parameters) drifting = drifting || p.drifting;
  // Re-armed once the slopes have been within bounds for a window length: a slope test that
  // has just crossed its threshold by chance tends to cross it again before its data renew.
  // Clear means every slope's estimate is within drift_per_hour, not merely insignificant: a
  // short trend after a new segment is too noisy to be significant while the drift goes on.
  bool clear = true;
  for (const auto& p : d.parameters)
    clear = clear && !(p.tested && std::abs(p.relative_per_hour) >= settings_.drift_per_hour);
  if (!drifting) {
    if (!clear) {
      drift_clear_since_ = std::numeric_limits<double>::quiet_NaN();
    } else {
      if (!(drift_clear_since_ <= w.t_end)) drift_clear_since_ = w.t_end;
      if (w.t_end - drift_clear_since_ >= w.length()) drift_armed_ = true;
    }
    return;
  }
  drift_clear_since_ = std::numeric_limits<double>::quiet_NaN();
  if (!drift_armed_) return;
  raise_drift(w.t_end, d.parameters, history_.front().t_begin, -1);
}

void HealthMonitor::raise_drift(double t, const std::array<ParameterTrend, kParams>& trend,
                                double onset, int parameter, const ParameterMask& candidates) {
  drift_armed_ = false;
  drift_clear_since_ = std::numeric_limits<double>::quiet_NaN();
  ++report_.drifts;
  HealthEvent e;
  e.kind = EventKind::drift;
  e.t = t;
  e.trend = trend;
  e.change.onset = onset;
  e.change.detected_at = t;
  e.change.parameter = parameter;
  e.change.candidates = candidates;
  if (report_.state == State::ok) set_state(State::drift, t);
  e.state = report_.state;
  events_.push_back(e);
}

void HealthMonitor::raise_change(const ChangePoint& change) {
  if (absorbed_by_chain(change)) return;
  start_chain(change);
  ++report_.changes;
  report_.has_change = true;
  report_.change = change;
  set_state(State::changed, change.detected_at);
  push_change_event(EventKind::changed, change);
  start_segment(change.onset, change.detected_at);
}

void HealthMonitor::push_change_event(EventKind kind, const ChangePoint& change) {
  HealthEvent e;
  e.kind = kind;
  e.t = change.detected_at;
  e.state = report_.state;
  e.change = change;
  events_.push_back(e);
}

// A new segment: the trends and the references start again after the onset.
void HealthMonitor::start_segment(double onset, double t) {
  segment_start_ = onset;
  first_segment_ = false;
  pending_.active = false;
  std::erase_if(history_, [&](const WindowEstimate& h) { return h.t_begin < segment_start_; });
  have_last_test_ = false;
  for (auto& c : cusums_) c.reset();
  alarm_waits_ = 0;
  innovation_.clear();
  accumulator_.restart();
  recent_blocks_.clear();
  recent_z_.clear();
  update_reference(t);
}

void HealthMonitor::set_state(State state, double t) {
  if (state == report_.state) return;
  report_.state = state;
  report_.since = t;
}

void HealthMonitor::acknowledge(double t) {
  if (report_.state == State::ok) return;
  // A change acknowledged is the actuator as it is now: the next alarm is a change of its own.
  // An acknowledged drift goes on silenced.
  if (report_.state == State::changed) chain_.active = false;
  ++report_.acknowledged;
  set_state(State::ok, t);
  HealthEvent e;
  e.kind = EventKind::acknowledged;
  e.t = t;
  e.state = State::ok;
  events_.push_back(e);
}

std::vector<HealthEvent> HealthMonitor::take_events() {
  std::vector<HealthEvent> out;
  out.swap(events_);
  return out;
}

}  // namespace scp::health

// The health monitor's fast detector: the reference model the residuals come from, the CUSUMs'
// design, the blocks, and an alarm's onset and isolation.
#include <algorithm>
#include <cmath>
#include <optional>

#include "health/departure_shape.hpp"
#include "health/monitor.hpp"

namespace scp::health {

namespace {

// Blocks kept for the isolation since an onset: the CUSUM's change point lies within the last
// few design delays, far less than this.
constexpr double kRecentBlocksSeconds = 900.0;
// How far before the CUSUM's change point a drift's start is searched.
constexpr double kRampSearchSeconds = 600.0;
// A ramp must fit better than a step, and a jump must not improve the ramp, by this much (χ²₁ at
// 0.999, in units of the fit's residual scale): right after a step the few blocks since it fit
// both shapes alike, and the step is the fast detector's design.
constexpr double kRampMargin = 10.83;
constexpr double kRampMinEvidenceSeconds = 20.0;
// How many blocks a fast alarm may wait for a block after its onset to name it from.
constexpr int kAlarmWaitBlocks = 2;

}  // namespace

Reference HealthMonitor::reference_at(double t) const {
  Reference r = reference_;
  if (r.valid && reference_fit_.with_slope)
    r.theta += reference_fit_.slope * (t - reference_fit_.t_eval);
  return r;
}

// The reference for the residuals from time t on: the trend of the windows that ended one window
// length before t (a window since then may already straddle a change the CUSUM has not yet
// found); while there are fewer than two of those (the first window length of a segment), the
// trend of every window so far. None before the segment's first live window.
void HealthMonitor::update_reference(double t) {
  Prediction p = predict(t, t - last_window_length_);
  // The residuals are independent of the reference from the end of its windows' data on.
  double data_end = t - last_window_length_;
  if (!p.valid || p.fit.windows < 2) {
    p = predict(t, t);
    data_end = t;
  }
  if (history_.empty()) p.valid = false;
  ++reference_.generation;
  // A change still being named keeps the reference it departed from until the new one exists.
  if (p.valid) naming_.active = false;
  if (!p.valid && naming_.active) {
    p.valid = true;
    p.fit = naming_.reference;
  }
  reference_.valid = p.valid;
  reference_fit_ = p.fit;
  if (!p.valid) {
    innovation_.clear();
    return;
  }
  reference_.theta = p.fit.level;
  reference_.covariance = p.fit.level_covariance;
  innovation_.set_reference(reference_.theta, reference_.covariance, data_end, t);
}

// Per parameter i: the design shift in z units, δ_i = design_change·|θ_i|·√Ī_ii (Ī the mean
// information per block). The CUSUMs' input is the blocks' innovations (innovation.hpp), from
// which the reference's own error is estimated out: N(0, 1) whatever it is, so the design needs
// no allowance for it. The false-alarm budget is shared equally.
void HealthMonitor::design_cusums() {
  if (information_blocks_ == 0 || !reference_.valid) return;
  int free = 0;
  for (int i = 0; i < kParams; ++i) free += mean_information_(i, i) > 0.0 ? 1 : 0;
  if (free == 0) return;
  const double arl0_blocks = free / (rate_per_detector_ * settings_.block_s);
  for (int i = 0; i < kParams; ++i) {
    const double info = mean_information_(i, i);
    if (!(info > 0.0)) continue;
    const double shift = settings_.design_change * std::abs(reference_.theta[i]) * std::sqrt(info);
    const CusumDesign d = design_cusum(shift, arl0_blocks, 0.0);
    cusums_[i].set_design(d);
    report_.fast.design[i] = d;
    report_.fast.design_delay_s[i] = cusum_delay(d, shift) * settings_.block_s;
  }
}

void HealthMonitor::add_sample(double t, const Vector2& residual, const Matrix26& sensitivity) {
  add_sample(t, residual, sensitivity, Matrix2N::Zero(), 0);
}

void HealthMonitor::add_sample(double t, const Vector2& residual, const Matrix26& sensitivity,
                               const Matrix2N& nuisance, std::uint64_t segment) {
  if (!reference_.valid) return;
  if (accumulator_.add(t, residual, sensitivity, nuisance, segment)) add_block(accumulator_.last());
}

void HealthMonitor::add_block(const ScoreBlock& block) {
  if (!reference_.valid || block.samples == 0 || !block.score.allFinite() ||
      !block.information.allFinite())
    return;
  if (naming_.active) {
    name_block(block);
    return;
  }
  // The CUSUMs' input; none for a block against a reference the monitor has left (the last one
  // before a change, or against the reference a named change departed from).
  const std::optional<Vector6> z = innovation_.add(block);
  if (!z) return;
  recent_blocks_.push_back(block);
  recent_z_.emplace_back(block.t_begin, *z);
  const double oldest = block.t_end - kRecentBlocksSeconds;
  std::erase_if(recent_blocks_, [oldest](const ScoreBlock& b) { return b.t_end < oldest; });
  std::erase_if(recent_z_, [oldest](const auto& b) { return b.first < oldest; });
  // The running mean of the information per block, then an exponential mean over ~1000 blocks.
  ++information_blocks_;
  const double weight =
      1.0 / static_cast<double>(std::min<std::uint64_t>(information_blocks_, 1000));
  mean_information_ += weight * (block.information - mean_information_);
  if (information_blocks_ == 1) {
    design_cusums();
    return;  // the first block designs the CUSUMs; they start with the next
  }
  FastReport& f = report_.fast;
  f.active = true;
  ++f.blocks;
  bool alarm = false;
  for (int i = 0; i < kParams; ++i) {
    if (!(block.information(i, i) > 0.0) || !(mean_information_(i, i) > 0.0)) continue;
    alarm = cusums_[i].update((*z)[i], block.t_begin) || alarm;
    f.ratio[i] = cusums_[i].ratio();
  }
  if (alarm) fast_alarm(block);
}

// A drift that starts late makes the reference lag behind it until the trend catches up: the
// residual grows from zero where a step's jumps (departure_shape.hpp). A ramp that fits the
// recent blocks' single-parameter estimates clearly better than a step, with no significant jump
// at its start, raises `drift` from its start and starts a new segment there. Otherwise `onset`
// becomes the step fit's change point: the CUSUM's (where it last stood at zero) comes early
// when the statistic crept up on the reference's error before the step, and the change summed
// from there is diluted by the blocks before it.
bool HealthMonitor::late_drift(int parameter, double& onset) {
  // A step alarms within a few blocks of its onset, and over so few any two-parameter shape
  // fits: only an alarm that took longer to build up can be a drift.
  if (recent_blocks_.empty() || recent_blocks_.back().t_end - onset < kRampMinEvidenceSeconds)
    return false;
  const DepartureShape shape = fit_departure(recent_blocks_, parameter, onset, kRampSearchSeconds);
  if (!shape.is_drift(kRampMargin)) {
    if (shape.step.valid) onset = shape.step.onset;
    return false;
  }
  std::array<ParameterTrend, kParams> trend{};
  ParameterTrend& p = trend[parameter];
  const double theta = std::abs(reference_at(shape.ramp.onset).theta[parameter]);
  p.tested = true;
  p.per_hour = shape.ramp.slope * 3600.0;
  p.relative_per_hour = theta > 0.0 ? p.per_hour / theta : 0.0;
  p.drifting = true;
  const double t = recent_blocks_.back().t_end;
  if (drift_armed_) raise_drift(t, trend, shape.ramp.onset, parameter);
  start_segment(shape.ramp.onset, t);
  return true;
}

// The CUSUM's change point (where it last stood at zero) comes early when its statistic stood
// above zero by chance before the change. The onset is the block start τ from there on that
// maximizes the GLR of a step of unknown size in the parameter's z, (Σ_{b≥τ} z_b)²/n_τ
// (Basseville and Nikiforov §2.4.3).
double HealthMonitor::step_onset(int parameter, double cusum_onset) const {
  double onset = cusum_onset, best = -1.0, sum = 0.0;
  int n = 0;
  for (auto b = recent_z_.rbegin(); b != recent_z_.rend() && b->first >= cusum_onset; ++b) {
    sum += b->second[parameter];
    ++n;
    if (sum * sum / n > best) {
      best = sum * sum / n;
      onset = b->first;
    }
  }
  return onset;
}

// The blocks' view of a sure alarm's departure (departure_shape.hpp): the windows' shapes
// (monitor_confirm.cpp) blur the start of a drift over a window length, the blocks resolve it to
// seconds. A drift slow enough for the innovations to absorb it never raises the fast alarm that
// would ask them (innovation.hpp), so the sure detector asks.
bool HealthMonitor::blocks_show_drift(int parameter, double onset, ShapeFit& ramp) const {
  if (recent_blocks_.empty()) return false;
  const DepartureShape shape = fit_departure(recent_blocks_, parameter, onset, kRampSearchSeconds);
  ramp = shape.ramp;
  return shape.is_drift(kRampMargin);
}

void HealthMonitor::fast_alarm(const ScoreBlock& block) {
  int channel = 0;
  for (int i = 1; i < kParams; ++i)
    if (cusums_[i].ratio() > cusums_[channel].ratio()) channel = i;
  const double cusum_onset = cusums_[channel].onset();
  double onset = step_onset(channel, cusum_onset);
  const auto sum_since = [this](double from) {
    ScoreBlock sum;
    for (const auto& b : recent_blocks_)
      if (b.t_begin >= from) sum.add(b);
    return sum;
  };
  // Whether the change matters and whether it is a step: from the plain sums since the onset
  // (every block, the one the change began in too), as the CUSUMs see them.
  const ScoreBlock since = sum_since(onset);
  const Isolation iso = isolate(since.score, since.information);
  const double theta = std::abs(reference_at(onset).theta[std::max(iso.parameter, 0)]);
  if (iso.parameter < 0 || !(std::abs(iso.delta) >= settings_.min_relative_change * theta)) {
    ++report_.dismissed;
    for (auto& c : cusums_) c.reset();
    return;
  }
  if (late_drift(iso.parameter, onset)) return;
  // Which parameter: from the blocks after the onset's, with the nuisance (naming.hpp). After
  // the CUSUM's change point's, not the step fit's: a thermal change's z grows with T̄'s
  // response over seconds, and the step fit's onset moves later with every block.
  const ChangeEvidence evidence = weigh_change(recent_blocks_, naming_start(cusum_onset),
                                               reference_at(onset).theta, naming_settings());
  // An alarm in the block after the change's has no block yet that lies wholly after its onset,
  // and would name every parameter as a candidate: it waits for such a block (the CUSUM stays
  // above h after a real change; the onset may move by a block meanwhile), so that the `changed`
  // event can name what the data already separate.
  const bool no_evidence = evidence.outputs[0].samples == 0 && evidence.outputs[1].samples == 0;
  if (no_evidence && alarm_waits_ < kAlarmWaitBlocks) {
    ++alarm_waits_;
    return;
  }
  alarm_waits_ = 0;
  const ChangePoint c = fast_change(evidence, sum_since(onset), onset, block.t_end);
  if (absorbed_by_chain(c)) return;
  if (!c.definite) {
    // Named later, from the residuals since the onset against the reference it departed from.
    naming_.active = true;
    naming_.change = c;
    naming_.reference = reference_fit_;
    naming_.blocks.clear();
    for (const auto& b : recent_blocks_)
      if (b.t_begin >= onset) naming_.blocks.push_back(b);
    naming_.by_windows = true;
    naming_.next_window_from = onset;
    naming_.windows_before.clear();
    naming_.windows_after.clear();
    for (const auto& w : history_)
      if (w.t_end <= onset) naming_.windows_before.push_back(w);
  }
  raise_change(c);
}

}  // namespace scp::health

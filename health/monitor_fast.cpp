// The health monitor's fast detector: the reference model the residuals come from, the CUSUMs'
// design, the blocks, and an alarm's onset and isolation.
#include <algorithm>
#include <cmath>

#include "health/monitor.hpp"

namespace scp::health {

namespace {

// Blocks kept for the isolation since an onset: the CUSUM's change point lies within the last
// few design delays, far less than this.
constexpr double kRecentBlocksSeconds = 900.0;

}  // namespace

Reference HealthMonitor::reference_at(double t) const {
  Reference r = reference_;
  if (r.valid && reference_fit_.with_slope)
    r.theta += reference_fit_.slope * (t - reference_fit_.t_eval);
  return r;
}

// The reference for the residuals from time t on: the trend of the windows that ended one window
// length before t (a window since then may already straddle a change the CUSUM has not yet
// found); right after a change, any window entirely after it.
void HealthMonitor::update_reference(double t) {
  Prediction p = predict(t, t - last_window_length_);
  if (!p.valid && !first_segment_) p = predict(t, t);
  ++reference_.generation;
  reference_.valid = p.valid;
  reference_fit_ = p.fit;
  if (!p.valid) return;
  reference_.theta = p.fit.level;
  reference_.covariance = p.fit.level_covariance;
}

// Per parameter i: the design shift in z units, δ_i = design_change·|θ_i|·√Ī_ii (Ī the mean
// information per block), and the bias the reference's own error e ~ N(0, C_ref) puts into z_i,
// (Ī e)_i/√Ī_ii, of variance (Ī C_ref Ī)_ii/Ī_ii. The false-alarm budget is shared equally.
void HealthMonitor::design_cusums() {
  if (information_blocks_ == 0 || !reference_.valid) return;
  int free = 0;
  for (int i = 0; i < kParams; ++i) free += mean_information_(i, i) > 0.0 ? 1 : 0;
  if (free == 0) return;
  const double arl0_blocks = free / (rate_per_detector_ * settings_.block_s);
  const Matrix6 spread = mean_information_ * reference_.covariance * mean_information_;
  for (int i = 0; i < kParams; ++i) {
    const double info = mean_information_(i, i);
    if (!(info > 0.0)) continue;
    const double shift = settings_.design_change * std::abs(reference_.theta[i]) * std::sqrt(info);
    const double bias_variance = std::max(0.0, spread(i, i) / info);
    const CusumDesign d = design_cusum(shift, arl0_blocks, bias_variance);
    cusums_[i].set_design(d);
    report_.fast.design[i] = d;
    report_.fast.design_delay_s[i] = cusum_delay(d, shift) * settings_.block_s;
  }
}

void HealthMonitor::add_sample(double t, const Vector2& residual, const Matrix26& sensitivity) {
  if (!reference_.valid) return;
  if (accumulator_.add(t, residual, sensitivity)) add_block(accumulator_.last());
}

void HealthMonitor::add_block(const ScoreBlock& block) {
  if (!reference_.valid || block.samples == 0 || !block.score.allFinite() ||
      !block.information.allFinite())
    return;
  recent_blocks_.push_back(block);
  const double oldest = block.t_end - kRecentBlocksSeconds;
  std::erase_if(recent_blocks_, [oldest](const ScoreBlock& b) { return b.t_end < oldest; });
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
  const Vector6 z = block.z();
  bool alarm = false;
  for (int i = 0; i < kParams; ++i) {
    if (!(block.information(i, i) > 0.0) || !(mean_information_(i, i) > 0.0)) continue;
    alarm = cusums_[i].update(z[i], block.t_begin) || alarm;
    f.ratio[i] = cusums_[i].ratio();
  }
  if (alarm) fast_alarm(block);
}

void HealthMonitor::fast_alarm(const ScoreBlock& block) {
  int channel = 0;
  for (int i = 1; i < kParams; ++i)
    if (cusums_[i].ratio() > cusums_[channel].ratio()) channel = i;
  const double onset = cusums_[channel].onset();
  ScoreBlock since;
  for (const auto& b : recent_blocks_)
    if (b.t_begin >= onset) since.add(b);
  const Isolation iso = isolate(since.score, since.information);
  const double theta = std::abs(reference_at(onset).theta[std::max(iso.parameter, 0)]);
  if (iso.parameter < 0 || !(std::abs(iso.delta) >= settings_.min_relative_change * theta)) {
    ++report_.dismissed;
    for (auto& c : cusums_) c.reset();
    return;
  }
  ChangePoint c;
  c.detector = Detector::fast;
  c.onset = onset;
  c.detected_at = block.t_end;
  c.parameter = iso.parameter;
  const Vector6 ref = reference_at(onset).theta;
  for (int i = 0; i < kParams; ++i) {
    const double info = since.information(i, i);
    ParameterShift& p = c.parameters[i];
    p.tested = info > 0.0;
    if (!p.tested) continue;
    p.delta = since.score[i] / info;
    p.sigma = 1.0 / std::sqrt(info);
    p.z = p.delta / p.sigma;
    p.relative = ref[i] != 0.0 ? p.delta / std::abs(ref[i]) : 0.0;
    p.moved = i == iso.parameter;
  }
  raise_change(c);
}

}  // namespace scp::health

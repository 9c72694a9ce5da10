#include "health/score_blocks.hpp"

#include <cmath>

namespace scp::health {

Vector6 ScoreBlock::z() const noexcept {
  Vector6 out = Vector6::Zero();
  for (int i = 0; i < kParams; ++i)
    if (information(i, i) > 0.0) out[i] = score[i] / std::sqrt(information(i, i));
  return out;
}

Vector2 ScoreBlock::output_z() const noexcept {
  if (samples == 0) return Vector2::Zero();
  return residual_sum / std::sqrt(static_cast<double>(samples));
}

void ScoreBlock::add(const ScoreBlock& other) noexcept {
  if (other.samples == 0) return;
  if (samples == 0) t_begin = other.t_begin;
  t_end = other.t_end;
  samples += other.samples;
  score += other.score;
  information += other.information;
  residual_sum += other.residual_sum;
}

bool BlockAccumulator::add(double t, const Vector2& residual,
                           const Matrix26& sensitivity) noexcept {
  if (!std::isfinite(t) || !residual.allFinite() || !sensitivity.allFinite()) return false;
  if (open_.samples == 0) open_.t_begin = t;
  open_.t_end = t;
  ++open_.samples;
  open_.score.noalias() += sensitivity.transpose() * residual;
  open_.information.noalias() += sensitivity.transpose() * sensitivity;
  open_.residual_sum += residual;
  // Closes on the sample that completes block_s counted from the first one (half a sample of
  // tolerance is not known here, so a relative epsilon absorbs the sums of periods).
  if (t - open_.t_begin < block_s_ * (1.0 - 1e-9)) return false;
  last_ = open_;
  open_ = ScoreBlock{};
  return true;
}

Isolation isolate(const Vector6& score, const Matrix6& information) noexcept {
  Isolation out;
  for (int i = 0; i < kParams; ++i) {
    const double info = information(i, i);
    if (!(info > 0.0) || !std::isfinite(score[i])) continue;
    out.glr[i] = score[i] * score[i] / info;
    if (out.parameter < 0 || out.glr[i] > out.glr[out.parameter]) out.parameter = i;
  }
  if (out.parameter >= 0) {
    const double info = information(out.parameter, out.parameter);
    out.delta = score[out.parameter] / info;
    out.sigma = 1.0 / std::sqrt(info);
  }
  return out;
}

}  // namespace scp::health

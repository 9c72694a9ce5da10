#include "health/score_blocks.hpp"

#include <Eigen/Eigenvalues>
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
  for (std::size_t k = 0; k < outputs.size(); ++k) outputs[k].add(other.outputs[k]);
}

void OutputSums::add(const OutputSums& other) noexcept {
  score += other.score;
  information += other.information;
  nuisance_score += other.nuisance_score;
  nuisance_information += other.nuisance_information;
  cross_information += other.cross_information;
  residual_square += other.residual_square;
}

bool BlockAccumulator::add(double t, const Vector2& residual, const Matrix26& sensitivity,
                           const Matrix2N& nuisance, std::uint64_t segment) noexcept {
  if (!std::isfinite(t) || !residual.allFinite() || !sensitivity.allFinite() ||
      !nuisance.allFinite())
    return false;
  // A new segment's nuisance columns are other parameters: the open block ends where it is.
  const bool split = open_.samples > 0 && open_.segment != segment;
  if (split) last_ = open_;
  if (split || open_.samples == 0) open_ = ScoreBlock{};
  if (open_.samples == 0) {
    open_.t_begin = t;
    open_.segment = segment;
  }
  open_.t_end = t;
  ++open_.samples;
  open_.score.noalias() += sensitivity.transpose() * residual;
  open_.information.noalias() += sensitivity.transpose() * sensitivity;
  open_.residual_sum += residual;
  for (int k = 0; k < 2; ++k) {
    OutputSums& o = open_.outputs[static_cast<std::size_t>(k)];
    const double e = residual[k];
    o.score.noalias() += sensitivity.row(k).transpose() * e;
    o.information.noalias() += sensitivity.row(k).transpose() * sensitivity.row(k);
    o.nuisance_score.noalias() += nuisance.row(k).transpose() * e;
    o.nuisance_information.noalias() += nuisance.row(k).transpose() * nuisance.row(k);
    o.cross_information.noalias() += sensitivity.row(k).transpose() * nuisance.row(k);
    o.residual_square += e * e;
  }
  if (split) return true;
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

namespace {

// Adds one segment's sums to `out` with its nuisance profiled out. I_NN⁺ is the pseudo-inverse:
// a column the segment does not excite (ẋ0 in a short one, an offset held known) drops out.
void add_profiled(ProfiledSum& out, const OutputSums& segment, const ScoreBlock& span) {
  const Eigen::SelfAdjointEigenSolver<NuisanceMatrix> eig(segment.nuisance_information);
  NuisanceMatrix pinv = NuisanceMatrix::Zero();
  if (eig.info() == Eigen::Success) {
    const double largest = eig.eigenvalues().cwiseAbs().maxCoeff();
    for (int k = 0; k < kNuisance; ++k) {
      const double e = eig.eigenvalues()[k];
      if (e > 1e-12 * largest && e > 0.0)
        pinv += eig.eigenvectors().col(k) * eig.eigenvectors().col(k).transpose() / e;
    }
  }
  const Matrix6N c = segment.cross_information * pinv;
  out.score += segment.score - c * segment.nuisance_score;
  out.information += segment.information - c * segment.cross_information.transpose();
  out.residual_square +=
      segment.residual_square - segment.nuisance_score.dot(pinv * segment.nuisance_score);
  if (out.samples == 0) out.t_begin = span.t_begin;
  out.t_end = span.t_end;
  out.samples += span.samples;
}

}  // namespace

ProfiledSum profile_nuisance(std::span<const ScoreBlock> blocks, double from, int output) {
  const auto k = static_cast<std::size_t>(output);
  ProfiledSum out;
  ScoreBlock segment;
  for (const ScoreBlock& b : blocks) {
    if (b.t_begin < from || b.samples == 0) continue;
    if (segment.samples > 0 && segment.segment != b.segment) {
      add_profiled(out, segment.outputs[k], segment);
      segment = ScoreBlock{};
    }
    if (segment.samples == 0) segment.segment = b.segment;
    segment.add(b);
  }
  if (segment.samples > 0) add_profiled(out, segment.outputs[k], segment);
  return out;
}

}  // namespace scp::health

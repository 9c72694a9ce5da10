#include "health/departure_shape.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>

namespace scp::health {

namespace {

constexpr int kShapeParameters = 3;  // onset, jump, slope of the jump+ramp

// The regressors of one shape at time t for onset s: g = ([t ≥ s], (t − s)⁺).
Eigen::Vector2d regressors(double t, double s) noexcept {
  return {t >= s ? 1.0 : 0.0, std::max(0.0, t - s)};
}

// Weighted least squares of δ_b on the regressors `mask` selects, for one onset: with
// A = Σ I·g·gᵀ and c = Σ g·s_b (Σ g·I·δ = Σ g·s), β = A⁻¹c and sse = total − cᵀβ.
ShapeFit fit_at(std::span<const ScoreBlock> blocks, int parameter, double s, double total,
                bool use_jump, bool use_slope) {
  Eigen::Matrix2d a = Eigen::Matrix2d::Zero();
  Eigen::Vector2d c = Eigen::Vector2d::Zero();
  for (const auto& b : blocks) {
    const double info = b.information(parameter, parameter);
    if (!(info > 0.0)) continue;
    Eigen::Vector2d g = regressors(0.5 * (b.t_begin + b.t_end), s);
    if (!use_jump) g[0] = 0.0;
    if (!use_slope) g[1] = 0.0;
    a += info * g * g.transpose();
    c += g * b.score[parameter];
  }
  // An unused regressor's row and column are zero: give it a unit pivot (its β stays 0).
  for (int k = 0; k < 2; ++k)
    if (!(a(k, k) > 0.0)) a(k, k) = 1.0;
  if (use_jump && use_slope && !(a(0, 0) * a(1, 1) - a(0, 1) * a(1, 0) > 0.0)) return {};
  const Eigen::Vector2d beta = a.ldlt().solve(c);
  if (!beta.allFinite()) return {};
  return {true, total - c.dot(beta), s, beta[0], beta[1]};
}

}  // namespace

bool DepartureShape::is_drift(double margin) const noexcept {
  if (!step.valid || !ramp.valid) return false;
  const bool ramp_fits_better = step.sse - ramp.sse > margin * noise_scale;
  const bool jump_significant = jump_ramp.valid && jump_ramp.jump * step.jump > 0.0 &&
                                ramp.sse - jump_ramp.sse > margin * noise_scale;
  return ramp_fits_better && !jump_significant;
}

DepartureShape fit_departure(std::span<const ScoreBlock> blocks, int parameter, double cusum_onset,
                             double search_before_s) {
  DepartureShape shape;
  double total = 0.0;
  for (const auto& b : blocks) {
    const double info = b.information(parameter, parameter);
    if (!(info > 0.0)) continue;
    total += b.score[parameter] * b.score[parameter] / info;
    ++shape.blocks;
  }
  if (shape.blocks == 0) return shape;
  const auto keep_best = [](ShapeFit& best, const ShapeFit& f) {
    if (f.valid && (!best.valid || f.sse < best.sse)) best = f;
  };
  const double first = cusum_onset - search_before_s;
  for (const auto& candidate : blocks) {
    if (candidate.t_begin < first) continue;
    const double s = candidate.t_begin;
    keep_best(shape.step, fit_at(blocks, parameter, s, total, true, false));
    keep_best(shape.ramp, fit_at(blocks, parameter, s, total, false, true));
    keep_best(shape.jump_ramp, fit_at(blocks, parameter, s, total, true, true));
  }
  if (shape.jump_ramp.valid && shape.blocks > kShapeParameters)
    shape.noise_scale =
        std::max(1.0, shape.jump_ramp.sse / static_cast<double>(shape.blocks - kShapeParameters));
  return shape;
}

}  // namespace scp::health

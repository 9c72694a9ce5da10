#pragma once
// Synthetic refined windows and score blocks with the error structure of the real ones, for the
// health tests and bench/bench_health_calibration.cpp.
//
// Information accrues uniformly in time: each chunk of `chunk_s` (the refit interval) carries an
// independent estimate of θ at its midpoint with covariance Q/chunk_s, and a window is the mean
// of its chunks (covariance Q/L), so overlapping windows share exactly their common chunks. A
// score block of `block_s` against a reference θ_ref is s ~ N(I·(θ − θ_ref), I) with I =
// block_s·Q⁻¹: the linearized output-error model ε = J·∆θ + noise.

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <deque>
#include <functional>
#include <random>

#include "health/score_blocks.hpp"
#include "health/types.hpp"

namespace scp::health::test {

using ThetaOfTime = std::function<Vector6(double)>;

// The paper's θ (PAPER-NOTES) and a covariance for 300 s shaped like the refined fit's at N1:
// θ1..θ4 σ ~0.8 % and strongly correlated (their common scale), θ5, θ6 σ ~1e-5 relative.
inline Vector6 paper_theta() {
  Vector6 t;
  t << 1247.0, 0.8, 1813.0, 0.1, 0.0594059, 1.10011;
  return t;
}

inline Matrix6 window_covariance_300s(double mech_rel = 0.008, double thermal_rel = 1e-5) {
  Matrix6 r = Matrix6::Identity();
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j)
      if (i != j) r(i, j) = 0.95;
  r(4, 5) = r(5, 4) = 0.9;
  Vector6 s = paper_theta();
  s.head<4>() *= mech_rel;
  s.tail<2>() *= thermal_rel;
  return s.asDiagonal() * r * s.asDiagonal();
}

class WindowStream {
 public:
  WindowStream(ThetaOfTime theta, const Matrix6& window_covariance, double window_s, double chunk_s,
               std::uint64_t seed)
      : theta_(std::move(theta)),
        q_(window_covariance * window_s),
        chol_((q_ / chunk_s).llt().matrixL()),
        window_s_(window_s),
        chunk_s_(chunk_s),
        chunks_per_window_(static_cast<int>(std::lround(window_s / chunk_s))),
        rng_(seed) {}

  // The next window, ending one chunk after the previous one (the first ends at t0 + window_s).
  WindowEstimate next() {
    while (static_cast<int>(chunks_.size()) < chunks_per_window_) add_chunk();
    if (static_cast<int>(chunks_.size()) > chunks_per_window_) chunks_.pop_front();
    WindowEstimate w;
    w.t_end = t_;
    w.t_begin = t_ - window_s_;
    for (const auto& c : chunks_) w.theta += c;
    w.theta /= static_cast<double>(chunks_.size());
    w.covariance = q_ / window_s_;
    add_chunk();
    return w;
  }
  double time() const { return t_; }
  const Matrix6& q() const { return q_; }

 private:
  void add_chunk() {
    Vector6 n;
    for (int i = 0; i < kParams; ++i) n[i] = normal_(rng_);
    chunks_.push_back(theta_(t_ + 0.5 * chunk_s_) + chol_ * n);
    t_ += chunk_s_;
  }

  ThetaOfTime theta_;
  Matrix6 q_;
  Matrix6 chol_;
  double window_s_, chunk_s_;
  int chunks_per_window_;
  std::deque<Vector6> chunks_;
  double t_ = 0.0;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_;
};

// A baseline: one window of independent data ending at t = 0.
inline WindowEstimate baseline_window(const Vector6& theta, const Matrix6& window_covariance,
                                      double window_s, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal;
  Vector6 n;
  for (int i = 0; i < kParams; ++i) n[i] = normal(rng);
  const Matrix6 l = window_covariance.llt().matrixL();
  WindowEstimate w;
  w.t_begin = -window_s;
  w.t_end = 0.0;
  w.theta = theta + l * n;
  w.covariance = window_covariance;
  return w;
}

class ScoreStream {
 public:
  static constexpr std::uint32_t kSamplesPerBlock = 1000;  // 1 kHz over 1 s

  ScoreStream(const Matrix6& information, std::uint64_t seed)
      : information_(information), chol_(information.llt().matrixL()), rng_(seed) {}

  ScoreBlock block(double t_begin, double t_end, const Vector6& theta, const Vector6& reference) {
    Vector6 n;
    for (int i = 0; i < kParams; ++i) n[i] = normal_(rng_);
    ScoreBlock b;
    b.t_begin = t_begin;
    b.t_end = t_end;
    b.samples = kSamplesPerBlock;
    b.information = information_;
    b.score = information_ * (theta - reference) + chol_ * n;
    // Each output's share: x sees θ1..θ4 and T̄ sees θ5, θ6 (the covariance has no cross terms
    // between the blocks), no nuisance; the residuals' squares are the part the six θ explain
    // plus the noise of the samples' other dimensions.
    for (int k = 0; k < kBlocks; ++k) {
      OutputSums& o = b.outputs[static_cast<std::size_t>(k)];
      const int first = kBlockFirst[k], size = kBlockEnd[k] - kBlockFirst[k];
      o.score.segment(first, size) = b.score.segment(first, size);
      o.information.block(first, first, size, size) = information_.block(first, first, size, size);
      const Eigen::VectorXd s = o.score.segment(first, size);
      const Eigen::MatrixXd i = o.information.block(first, first, size, size);
      o.residual_square = s.dot(i.ldlt().solve(s)) + (kSamplesPerBlock - size);
    }
    return b;
  }

 private:
  Matrix6 information_;
  Matrix6 chol_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_;
};

}  // namespace scp::health::test

#pragma once
// The fast detector's statistic with the reference's own error, and the residual simulation's
// nuisance, taken out by the residuals themselves.
//
// A block's score against the reference is s ~ N(I·e, I), e = θ − θ_ref the reference's error.
// That error is the same in every block until the reference is recomputed, so the plain
// efficient score z_i = s_i/√I_ii carries a bias (I e)_i/√I_ii that a CUSUM accumulates like a
// change: its threshold must allow for it (averaged over e ~ N(0, C_ref)), and since a 10 %
// change of a mechanical θ moves z by hundreds per block while the CUSUM's k stays ≤ 1 (cusum.hpp),
// that allowance raised h to 10⁴–10⁶ in the daemon's runs. But the residuals estimate e: with
// the reference as the prior, e ~ N(0, C_ref), and the blocks since the reference's data end
// (independent of it) as data, the posterior of η = [e, n] — n the nuisance of the current
// residual segment (its seed state and the outputs' offsets, score_blocks.hpp), flat — gives each
// block's efficient score for a change of θ_i alone given everything before it (the matched
// filter for that direction; Basseville and Nikiforov ch. 7, additive changes with a nuisance):
//
//   with the past's information A and the block's s, I (θ and nuisance, 11 × 11):
//   a = s − I·η̂⁺,  η̂⁺ = (A + I)⁻¹(b + s)  (the posterior mean with the block),
//   G = I − I (A + I)⁻¹ I,  z_i = a_i/√G_ii,
//
// which is the block's innovation's score I V⁻¹ ν with V = I + I A⁻¹ I where A is invertible,
// and is N(0, 1) and independent from block to block whatever e and n are. A change ∆ of θ_i
// gives z_i mean ≈ ∆·√G_ii at first, which the posterior absorbs only at the rate it accrues
// data (the blocks since the reference's data end, a window length and more, against the few
// blocks a CUSUM needs). With an exact reference and no nuisance, z_i is the plain s_i/√I_ii.
// A drift is absorbed as it goes.
//
// At a new segment its predecessor's nuisance is profiled out (its blocks keep their information
// about e); at a new reference θ' the segments kept are re-expressed against it (b −= A·(θ' − θ),
// exact for the linearized response), and those that began before its data end leave.

#include <cstdint>
#include <optional>
#include <vector>

#include "health/score_blocks.hpp"

namespace scp::health {

class InnovationScores {
 public:
  static constexpr int kDim = kParams + kNuisance;
  using VectorD = Eigen::Matrix<double, kDim, 1>;
  using MatrixD = Eigen::Matrix<double, kDim, kDim>;

  // A new reference: its θ and covariance, the loop time from which the residuals are
  // independent of it (its windows' data end before), and the time from which the blocks are
  // computed against it (a block that began before is against the previous one). A parameter
  // with zero variance is known.
  void set_reference(const Vector6& theta, const Matrix6& covariance, double data_end, double from);
  // The block's z against the reference corrected by the blocks before it (0 where the block
  // does not see a parameter); then the block joins the posterior. Blocks come in time order.
  // None for a block against no reference given since clear() (one that began before the first
  // reference's `from`: the residuals of a reference the monitor has left).
  std::optional<Vector6> add(const ScoreBlock& block);
  void clear() noexcept;

  // The posterior's estimate of θ − θ_ref (for tests and diagnostics).
  Vector6 error_estimate() const;

 private:
  struct PendingReference {
    bool active = false;
    Vector6 theta = Vector6::Zero();
    Matrix6 covariance = Matrix6::Zero();
    double data_end = 0.0;
    double from = 0.0;
  };
  // One residual segment's information about [e, n] (its nuisance profiled out once closed).
  struct Segment {
    std::uint64_t id = 0;
    double t_begin = 0.0;
    MatrixD information = MatrixD::Zero();
    VectorD score = VectorD::Zero();  // against theta_
  };
  void apply(const PendingReference& r);
  void close_open_segment();
  void totals(MatrixD& information, VectorD& score) const;

  PendingReference pending_;
  bool valid_ = false;
  Vector6 theta_ = Vector6::Zero();
  Matrix6 prior_precision_ = Matrix6::Zero();
  std::vector<Segment> closed_;
  Segment open_;
  bool has_open_ = false;
};

}  // namespace scp::health

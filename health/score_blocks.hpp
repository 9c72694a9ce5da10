#pragma once
// The fast detector's input: residuals of the reference model (simulated forward on the new
// samples), projected onto the model's sensitivities and summed over blocks.
//
// Per sample the caller passes r = ε/σ per output (x, T̄) and J = ∂(y/σ)/∂θ (refine's
// SensitivitySimulator, divided by each channel's noise σ). Over a block:
//   score s = Σ Jᵀ r,  information I = Σ Jᵀ J,  z_i = s_i / √I_ii.
// While θ = θ_ref and the noise is white, z_i ~ N(0, 1) and independent from block to block; a
// change ∆ in θ_i alone gives ε ≈ J_i ∆, so z_i has mean ∆·√I_ii whatever the sign of J_i:
// the efficient score (Basseville & Nikiforov's local approach). A plain block mean of ε_x does
// not have that property: a change of b/m shifts x's lag behind T̄, and the residual changes sign
// with every heating and cooling phase, so its mean over the excitation is near zero.

#include <array>
#include <cstdint>
#include <span>

#include "health/types.hpp"

namespace scp::health {

// The nuisance of a residual simulation: the model's state at the moment it was seeded (x, ẋ, T̄)
// and constant offsets of x and T̄ (the fit's x_zero and ambient offset). A step in θ at τ after
// the seed leaves a residual ∆·(J(t) − Φ(t, τ)·∂state(τ)/∂θ): the free response from τ lies in
// the span of the state's sensitivities from the seed, so over the samples after τ the nuisance
// columns absorb it exactly, and each segment (one seed) has its own.
inline constexpr int kNuisance = 5;
using NuisanceVector = Eigen::Matrix<double, kNuisance, 1>;
using NuisanceMatrix = Eigen::Matrix<double, kNuisance, kNuisance>;
using Matrix2N = Eigen::Matrix<double, 2, kNuisance>;
using Matrix6N = Eigen::Matrix<double, kParams, kNuisance>;

// One output's sums over a block: Σ jᵀe, Σ jᵀj with j = ∂(y/σ)/∂θ, the same with the nuisance's
// n = ∂(y/σ)/∂nuisance (Σ nᵀe, Σ nᵀn, Σ jᵀn), and Σ e².
struct OutputSums {
  Vector6 score = Vector6::Zero();
  Matrix6 information = Matrix6::Zero();
  NuisanceVector nuisance_score = NuisanceVector::Zero();
  NuisanceMatrix nuisance_information = NuisanceMatrix::Zero();
  Matrix6N cross_information = Matrix6N::Zero();
  double residual_square = 0.0;

  void add(const OutputSums& other) noexcept;
};

struct ScoreBlock {
  double t_begin = 0.0;  // s, first and last sample
  double t_end = 0.0;
  std::uint32_t samples = 0;
  Vector6 score = Vector6::Zero();
  Matrix6 information = Matrix6::Zero();
  Vector2 residual_sum = Vector2::Zero();  // Σ r per output
  // Per output (x, T̄), the sums with the nuisance sensitivities N (2×kNuisance per sample) of
  // the block's segment: a change is named from the output that sees its block (naming.hpp).
  std::uint64_t segment = 0;
  std::array<OutputSums, 2> outputs{};

  // z_i = s_i/√I_ii, 0 where I_ii = 0 (a parameter the outputs do not see in this block).
  Vector6 z() const noexcept;
  // Σ r / √n per output: N(0, 1) under the same conditions (for diagnostics).
  Vector2 output_z() const noexcept;
  void add(const ScoreBlock& other) noexcept;
};

class BlockAccumulator {
 public:
  explicit BlockAccumulator(double block_s) noexcept : block_s_(block_s) {}

  // Adds one sample; true when it closed a block (then last() holds it). A block spans block_s
  // from its first sample, or ends early where the segment changes (the sample then opens the
  // next block). Non-finite input is skipped.
  bool add(double t, const Vector2& residual, const Matrix26& sensitivity,
           const Matrix2N& nuisance = Matrix2N::Zero(), std::uint64_t segment = 0) noexcept;
  const ScoreBlock& last() const noexcept { return last_; }
  // Drops the open block (a gap in the samples, a new reference model).
  void restart() noexcept { open_ = ScoreBlock{}; }

 private:
  double block_s_;
  ScoreBlock open_, last_;
};

// The single parameter whose change alone best explains a score and information summed since a
// change: the generalized likelihood ratio of "only θ_i changed", Λ_i = s_i²/I_ii, is largest,
// and that change is ∆ = s_i/I_ii with σ = 1/√I_ii (one Gauss–Newton step in θ_i).
struct Isolation {
  int parameter = -1;
  double delta = 0.0;
  double sigma = 0.0;
  Vector6 glr = Vector6::Zero();  // Λ_i for every parameter (0 where not observed)
};
Isolation isolate(const Vector6& score, const Matrix6& information) noexcept;

// One output's sums over the blocks from `from` on, with each segment's nuisance profiled out
// (the Schur complement: s̃ = s − I_θN I_NN⁺ s_N, Ĩ = I_θθ − I_θN I_NN⁺ I_Nθ, per segment, then
// summed), and the residual sum of squares the nuisance alone leaves.
struct ProfiledSum {
  Vector6 score = Vector6::Zero();
  Matrix6 information = Matrix6::Zero();
  double residual_square = 0.0;
  std::uint64_t samples = 0;
  double t_begin = 0.0, t_end = 0.0;
};
ProfiledSum profile_nuisance(std::span<const ScoreBlock> blocks, double from, int output);

}  // namespace scp::health

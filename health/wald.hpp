#pragma once
// The sure detector's test: one refined window's θ̂ against a reference (the baseline, or the
// trend-extrapolated reference of health/trend.hpp), a Wald χ² with both covariances per block
// (mechanical θ1..θ4, thermal θ5, θ6) and a z per parameter:
//
//   d = θ̂ − θ_ref,  W_b = d_bᵀ (C_b + C_ref,b)⁻¹ d_b ~ χ²(p_b),  z_i = d_i / √(C_ii + C_ref,ii),
//
// p_b the block's free parameters (a parameter with zero variance in both was held known). The
// two estimates must be independent (windows that do not overlap, or a baseline from other data).

#include <array>

#include "health/types.hpp"

namespace scp::health {

struct ParameterShift {
  bool tested = false;    // free in both estimates
  double delta = 0.0;     // θ̂_i − θ_ref,i
  double sigma = 0.0;     // √(C_ii + C_ref,ii)
  double z = 0.0;         // delta / sigma
  double relative = 0.0;  // delta / |θ_ref,i| (0 when θ_ref,i = 0)
  // The change of θ_i alone that best explains the block's d (the others held):
  // (C⁻¹d)_i/(C⁻¹)_ii with σ 1/√(C⁻¹)_ii, and its likelihood ratio (C⁻¹d)_i²/(C⁻¹)_ii.
  double alone = 0.0;
  double alone_sigma = 0.0;
  double glr = 0.0;
  bool moved = false;  // named: see WaldThresholds
};

struct BlockWald {
  int dof = 0;
  double statistic = 0.0;
  double threshold = 0.0;
  bool significant = false;  // statistic > threshold (a non-finite statistic counts)
};

// In a significant block the parameter whose change alone best explains d (the largest GLR) is
// named first, and with it every parameter with |z_i| ≥ name_z; none whose change (alone for
// the first, marginal for the others) is below min_relative_change of |θ_ref,i| (a change too
// small to matter physically, or within a real bench's model misfit, is never named). The
// marginal z alone names badly where parameters are strongly correlated (θ1..θ4 share a common
// scale): a step in b/m first shows as a small marginal shift of every θ1..θ4.
struct WaldThresholds {
  std::array<double, kBlocks> block{};
  double name_z = 2.0;
  double min_relative_change = 0.0;
};

struct WaldResult {
  std::array<BlockWald, kBlocks> blocks{};
  std::array<ParameterShift, kParams> parameters{};
  std::array<int, kBlocks> first{-1, -1};  // the parameter named first per block, −1 if none
  // Some parameter is named.
  bool alarm() const noexcept;
  // The parameter named first with the largest GLR over the blocks, −1 if none.
  int first_named() const noexcept;
};

WaldResult wald_test(const Vector6& theta, const Matrix6& covariance, const Vector6& reference,
                     const Matrix6& reference_covariance, const WaldThresholds& thresholds);

}  // namespace scp::health

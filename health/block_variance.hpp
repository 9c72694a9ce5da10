#pragma once
// How far a residual's sums over the fast detector's blocks vary beyond what white noise gives
// them: the long-run variance ratio at the block's length,
//   ratio = lrv(S) / (n̄ · mean r²),   S = Σ over a block of r,   n̄ the samples per block,
// lrv(S) = γ0 + 2·(2/3)·γ1 + 2·(1/3)·γ2 with γj the block sums' lag-j autocovariance (Newey–West
// on the block sums, Bartlett's weights: noise correlated over a fair part of a block carries
// into the next, and the CUSUM adds blocks up). 1 for white noise, (1 + a)/(1 − a) for
// first-order Gauss–Markov noise of lag-one correlation a correlated over less than a block, and
// above 1 for any misfit the model leaves in the residual slowly. The detector's scores Σ Jᵀr
// assume white residuals; dividing r and J by √ratio makes its z N(0, 1) again.

#include <cstddef>

namespace scp::health {

class BlockVarianceRatio {
 public:
  explicit BlockVarianceRatio(double block_s) noexcept : block_s_(block_s) {}

  // One residual sample at time t (increasing), in units of its noise σ. Non-finite: ignored.
  void add(double t, double residual) noexcept;

  // Complete blocks so far.
  std::size_t blocks() const noexcept { return blocks_; }
  // The ratio estimated from the complete blocks; 1 with fewer than two.
  double ratio() const noexcept;
  // The ratio where it exceeds what white noise gives by chance (χ² with blocks − 1 degrees of
  // freedom, one-sided at 0.1 %), else 1: white residuals keep the detector's full sensitivity.
  double significant_ratio() const noexcept;

 private:
  void close_block() noexcept;

  double block_s_;
  double block_start_ = 0.0;
  bool started_ = false;
  double block_sum_ = 0.0, block_squares_ = 0.0;
  std::size_t block_samples_ = 0;
  std::size_t blocks_ = 0, samples_ = 0;
  double sum_of_sums_ = 0.0, sum_of_squared_sums_ = 0.0, sum_of_squares_ = 0.0;
  double sum_of_lag1_products_ = 0.0, sum_of_lag2_products_ = 0.0;
  double previous_sums_[2] = {0.0, 0.0};  // the last two complete blocks' sums
};

}  // namespace scp::health

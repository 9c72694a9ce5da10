#include "health/block_variance.hpp"

#include <algorithm>
#include <cmath>

namespace scp::health {

void BlockVarianceRatio::add(double t, double residual) noexcept {
  if (!std::isfinite(t) || !std::isfinite(residual)) return;
  if (!started_) {
    started_ = true;
    block_start_ = t;
  } else if (t - block_start_ >= block_s_) {
    close_block();
    block_start_ = t;
  }
  block_sum_ += residual;
  block_squares_ += residual * residual;
  ++block_samples_;
}

void BlockVarianceRatio::close_block() noexcept {
  ++blocks_;
  samples_ += block_samples_;
  sum_of_sums_ += block_sum_;
  sum_of_squared_sums_ += block_sum_ * block_sum_;
  if (blocks_ >= 2) sum_of_lag1_products_ += block_sum_ * previous_sums_[0];
  if (blocks_ >= 3) sum_of_lag2_products_ += block_sum_ * previous_sums_[1];
  previous_sums_[1] = previous_sums_[0];
  previous_sums_[0] = block_sum_;
  sum_of_squares_ += block_squares_;
  block_sum_ = block_squares_ = 0.0;
  block_samples_ = 0;
}

double BlockVarianceRatio::ratio() const noexcept {
  if (blocks_ < 2 || samples_ == 0) return 1.0;
  const double b = static_cast<double>(blocks_);
  const double mean = sum_of_sums_ / b;
  const double gamma0 = (sum_of_squared_sums_ - sum_of_sums_ * mean) / (b - 1.0);
  // The block sums' own lag-one and lag-two covariances (about the mean, to first order):
  // noise correlated over a fair part of a block carries from one block into the next, and the
  // CUSUM adds blocks up. Bartlett's weights keep the estimate non-negative.
  const double gamma1 = blocks_ >= 3 ? sum_of_lag1_products_ / (b - 1.0) - mean * mean : 0.0;
  const double gamma2 = blocks_ >= 4 ? sum_of_lag2_products_ / (b - 2.0) - mean * mean : 0.0;
  const double block_variance = std::max(gamma0 + (4.0 / 3.0) * gamma1 + (2.0 / 3.0) * gamma2, 0.0);
  const double per_sample = sum_of_squares_ / static_cast<double>(samples_);
  const double samples_per_block = static_cast<double>(samples_) / b;
  if (!(per_sample > 0.0)) return 1.0;
  const double r = block_variance / (samples_per_block * per_sample);
  return std::isfinite(r) ? r : 1.0;
}

double BlockVarianceRatio::significant_ratio() const noexcept {
  if (blocks_ < 2) return 1.0;
  // On white noise γ0/var ~ χ²_ν/ν ≈ N(1, 2/ν), and the Bartlett sum's variance is
  // 1 + 2·((2/3)² + (1/3)²) = 19/9 times that: the 0.999 quantile 1 + 3.09·√(38/(9ν)).
  const double dof = static_cast<double>(blocks_) - 1.0;
  const double threshold = 1.0 + 3.09 * std::sqrt(38.0 / (9.0 * dof));
  const double r = ratio();
  return r > threshold ? r : 1.0;
}

}  // namespace scp::health

// The block variance ratio (health/block_variance.hpp): 1 for white noise, (1 + a)/(1 − a) for
// first-order Gauss–Markov noise, and significant only where white noise would not reach it.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "health/block_variance.hpp"

namespace scp::health {
namespace {

constexpr double kPeriod = 1e-3;

BlockVarianceRatio feed(double lag_one, int samples, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal;
  BlockVarianceRatio ratio(1.0);
  const double innovation = std::sqrt(1.0 - lag_one * lag_one);
  double n = normal(rng);
  for (int k = 0; k < samples; ++k) {
    n = lag_one * n + innovation * normal(rng);
    ratio.add(k * kPeriod, n);
  }
  return ratio;
}

TEST(BlockVarianceRatio, WhiteNoiseGivesOneAndIsNotSignificant) {
  int significant = 0;
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    const BlockVarianceRatio r = feed(0.0, 120000, seed);  // a 120 s window at 1 kHz
    EXPECT_EQ(r.blocks(), 119U);                           // the last block is still open
    EXPECT_NEAR(r.ratio(), 1.0, 0.45);                     // σ of the estimate: √(2/118) = 0.13
    if (r.significant_ratio() != 1.0) ++significant;
  }
  EXPECT_LE(significant, 1);  // a 0.1 % test: 20 windows see none, rarely one
}

TEST(BlockVarianceRatio, GaussMarkovNoiseGivesItsLongRunVarianceRatio) {
  for (const double a : {0.5, 0.9, 0.951}) {
    const BlockVarianceRatio r = feed(a, 300000, 7);
    // Over blocks of 1000 samples the ratio is (1 + a)/(1 − a) less a boundary term of order
    // 2a/((1 − a)²·1000): under 1 % here.
    const double expected = (1.0 + a) / (1.0 - a);
    EXPECT_NEAR(r.ratio(), expected, 0.3 * expected) << a;
    EXPECT_EQ(r.significant_ratio(), r.ratio()) << a;
  }
}

// Noise correlated over a fifth of a block (τc 0.2 s): the block sums are correlated too, and
// their lag terms bring the ratio near the sums' long-run variance, which the CUSUM sees.
TEST(BlockVarianceRatio, NoiseCorrelatedOverAFairPartOfABlockCountsTheNextBlocks) {
  const double a = std::exp(-kPeriod / 0.2);
  const double long_run = (1.0 + a) / (1.0 - a);  // 399
  const BlockVarianceRatio r = feed(a, 3000000, 11);
  // The block sums' variance alone is 0.80 of it (n·(1 + a)/(1 − a) − 2a(1 − aⁿ)/(1 − a)²); the
  // estimate's σ over 3000 blocks is 4 %.
  EXPECT_GT(r.ratio(), 0.88 * long_run);
  EXPECT_LT(r.ratio(), 1.12 * long_run);
}

TEST(BlockVarianceRatio, TooFewBlocksAndNonFiniteInputLeaveOne) {
  BlockVarianceRatio r(1.0);
  EXPECT_EQ(r.ratio(), 1.0);
  for (int k = 0; k < 1500; ++k) r.add(k * kPeriod, k % 2 == 0 ? 1.0 : NAN);
  EXPECT_EQ(r.blocks(), 1U);
  EXPECT_EQ(r.ratio(), 1.0);
  EXPECT_EQ(r.significant_ratio(), 1.0);
}

}  // namespace
}  // namespace scp::health

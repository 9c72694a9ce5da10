// Blocks of residual scores: the sums, the block length, and the isolation of the parameter
// that alone explains a residual signature.
#include <gtest/gtest.h>

#include <Eigen/LU>
#include <random>

#include "health/score_blocks.hpp"
#include "tests/health/synthetic_windows.hpp"

namespace scp::health {
namespace {

TEST(ScoreBlocks, SumsOverTheBlockLength) {
  BlockAccumulator acc(1.0);
  Matrix26 j = Matrix26::Zero();
  j(0, 0) = 2.0;
  j(1, 4) = 3.0;
  int blocks = 0;
  for (int k = 1; k <= 3000; ++k) {
    if (acc.add(k * 1e-3, Vector2(1.0, -1.0), j)) {
      ++blocks;
      const ScoreBlock& b = acc.last();
      EXPECT_NEAR(b.t_end - b.t_begin, 1.0, 1e-9);
      EXPECT_NEAR(b.score[0], 2.0 * b.samples, 1e-9);
      EXPECT_NEAR(b.score[4], -3.0 * b.samples, 1e-9);
      EXPECT_NEAR(b.information(4, 4), 9.0 * b.samples, 1e-9);
      EXPECT_NEAR(b.z()[0], std::sqrt(double(b.samples)), 1e-9);
      EXPECT_NEAR(b.output_z()[1], -std::sqrt(double(b.samples)), 1e-9);
      EXPECT_EQ(b.z()[1], 0.0);  // unobserved
    }
  }
  EXPECT_EQ(blocks, 2);  // 1001 samples each (both ends counted), the third still open
  EXPECT_FALSE(acc.add(4.0, Vector2(std::nan(""), 0.0), j));
}

TEST(ScoreBlocks, IsolationNamesTheParameterThatMoved) {
  // Correlated sensitivities (θ5 and θ6 both heat T̄): over 30 blocks after a 2 % change in θ6
  // alone, the single-parameter GLR names θ6 and its size, in 95 of 100 seeds at least.
  const Vector6 theta = test::paper_theta();
  const Matrix6 c = test::window_covariance_300s(0.008, 1e-3);
  const Matrix6 info = (c * 300.0).inverse();  // per second
  Vector6 moved = theta;
  moved[5] *= 1.02;
  int named = 0;
  for (int seed = 0; seed < 100; ++seed) {
    test::ScoreStream s(info, seed);
    ScoreBlock sum;
    for (int k = 0; k < 30; ++k) sum.add(s.block(k, k + 1, moved, theta));
    const Isolation iso = isolate(sum.score, sum.information);
    if (iso.parameter == 5) {
      ++named;
      EXPECT_NEAR(iso.delta / (0.02 * theta[5]), 1.0, 6.0 * iso.sigma / (0.02 * theta[5]));
    }
  }
  EXPECT_GE(named, 95);
}

}  // namespace
}  // namespace scp::health

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

TEST(ScoreBlocks, ASegmentChangeEndsTheOpenBlock) {
  BlockAccumulator acc(1.0);
  const Matrix26 j = Matrix26::Ones();
  for (int k = 1; k <= 400; ++k) EXPECT_FALSE(acc.add(k * 1e-3, Vector2(1.0, 1.0), j, {}, 7));
  EXPECT_TRUE(acc.add(0.401, Vector2(1.0, 1.0), j, {}, 8));
  EXPECT_EQ(acc.last().samples, 400u);
  EXPECT_EQ(acc.last().segment, 7u);
}

TEST(ScoreBlocks, ProfilingRemovesEachSegmentsNuisance) {
  // r = J_3·∆ + N·c_segment exactly, with random sensitivities and a different nuisance c in
  // each of two segments: profiled, θ3's change alone explains everything, ∆ exactly, and the
  // residual sum left is Λ_3's.
  std::mt19937_64 rng(5);
  std::normal_distribution<double> normal;
  const double delta = 0.3;
  std::vector<ScoreBlock> blocks;
  BlockAccumulator acc(0.1);
  for (int k = 1; k <= 2000; ++k) {
    const std::uint64_t segment = k <= 1000 ? 1 : 2;
    NuisanceVector c;
    for (int m = 0; m < kNuisance; ++m) c[m] = segment == 1 ? 0.5 * m - 1.0 : 2.0 - m;
    Matrix26 j;
    Matrix2N n;
    for (int r = 0; r < 2; ++r) {
      for (int i = 0; i < kParams; ++i) j(r, i) = normal(rng);
      for (int m = 0; m < kNuisance; ++m) n(r, m) = normal(rng);
    }
    const Vector2 residual = j.col(2) * delta + n * c;
    if (acc.add(k * 1e-3, residual, j, n, segment)) blocks.push_back(acc.last());
  }
  const ProfiledSum x = profile_nuisance(blocks, 0.0, 0);
  const Isolation iso = isolate(x.score, x.information);
  EXPECT_EQ(iso.parameter, 2);
  EXPECT_NEAR(iso.delta, delta, 1e-9);
  EXPECT_NEAR(x.residual_square, iso.glr[2], 1e-6 * iso.glr[2]);
  // Unprofiled, the nuisance biases the change.
  ScoreBlock plain;
  for (const auto& b : blocks) plain.add(b);
  EXPECT_GT(std::abs(plain.outputs[0].score[2] / plain.outputs[0].information(2, 2) - delta), 0.01);
}

}  // namespace
}  // namespace scp::health

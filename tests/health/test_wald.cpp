// The Wald test of a window against a reference: the statistic by hand, known parameters, the
// naming rules, and its size under no change by simulation.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <random>

#include "health/distributions.hpp"
#include "health/wald.hpp"
#include "tests/health/synthetic_windows.hpp"

namespace scp::health {
namespace {

WaldThresholds thresholds(double mech, double thermal, double min_rel = 0.0) {
  WaldThresholds t;
  t.block = {mech, thermal};
  t.min_relative_change = min_rel;
  return t;
}

TEST(Wald, StatisticByHandOnADiagonalCase) {
  const Vector6 ref = test::paper_theta();
  Vector6 s;
  s << 10, 0.01, 15, 0.001, 1e-7, 1e-7;
  const Matrix6 c = s.cwiseAbs2().asDiagonal();
  const Vector6 theta = ref + s;  // one σ of each estimate: z = 1/√2, W = p/2
  const WaldResult r = wald_test(theta, c, ref, c, thresholds(100, 100));
  EXPECT_NEAR(r.blocks[0].statistic, 2.0, 1e-9);
  EXPECT_NEAR(r.blocks[1].statistic, 1.0, 1e-9);
  EXPECT_EQ(r.blocks[0].dof, 4);
  EXPECT_NEAR(r.parameters[2].z, 1.0 / std::sqrt(2.0), 1e-12);
  EXPECT_FALSE(r.alarm());
}

TEST(Wald, NamesTheParameterThatMovedAndHowMuch) {
  const Vector6 ref = test::paper_theta();
  const Matrix6 c = test::window_covariance_300s();
  Vector6 theta = ref;
  theta[4] *= 1.10;  // λ/Cth +10 %
  const WaldResult r = wald_test(theta, c, ref, c, thresholds(30, 30, 0.02));
  EXPECT_TRUE(r.blocks[1].significant);
  EXPECT_FALSE(r.blocks[0].significant);
  ASSERT_EQ(r.first_named(), 4);
  EXPECT_NEAR(r.parameters[4].relative, 0.10, 1e-12);
  EXPECT_NEAR(r.parameters[4].sigma, std::sqrt(2.0 * c(4, 4)), 1e-15);
  // θ6 is correlated with θ5 but did not move: not named.
  EXPECT_FALSE(r.parameters[5].moved);
  // The same change below min_relative_change is not named, however significant.
  theta[4] = ref[4] * 1.01;
  const WaldResult small = wald_test(theta, c, ref, c, thresholds(30, 30, 0.02));
  EXPECT_TRUE(small.blocks[1].significant);
  EXPECT_FALSE(small.alarm());
}

TEST(Wald, KnownParametersLeaveTheTest) {
  const Vector6 ref = test::paper_theta();
  Matrix6 c = test::window_covariance_300s();
  c.row(2).setZero();
  c.col(2).setZero();
  Vector6 theta = ref;
  theta[2] *= 3.0;  // known: ignored
  const WaldResult r = wald_test(theta, c, ref, c, thresholds(20, 20));
  EXPECT_EQ(r.blocks[0].dof, 3);
  EXPECT_FALSE(r.parameters[2].tested);
  EXPECT_FALSE(r.alarm());
}

TEST(Wald, SizeUnderNoChangeIsTheChiSquareTail) {
  // 20000 pairs of independent estimates with the refined fit's correlations: the fraction of
  // mechanical statistics beyond χ²₄'s 1 % point is 1 % within its binomial 3σ (0.21 %).
  const Matrix6 c = test::window_covariance_300s();
  const Matrix6 l = c.llt().matrixL();
  std::mt19937_64 rng(1);
  std::normal_distribution<double> n;
  const double q4 = chi_square_upper_quantile(0.01, 4), q2 = chi_square_upper_quantile(0.01, 2);
  int beyond[2] = {0, 0};
  const int draws = 20000;
  for (int k = 0; k < draws; ++k) {
    Vector6 a, b;
    for (int i = 0; i < kParams; ++i) {
      a[i] = n(rng);
      b[i] = n(rng);
    }
    const Vector6 ref = test::paper_theta();
    const WaldResult r = wald_test(ref + l * a, c, ref + l * b, c, thresholds(q4, q2));
    for (int blk = 0; blk < 2; ++blk) beyond[blk] += r.blocks[blk].significant ? 1 : 0;
  }
  EXPECT_NEAR(beyond[0] / double(draws), 0.01, 0.0021);
  EXPECT_NEAR(beyond[1] / double(draws), 0.01, 0.0021);
}

}  // namespace
}  // namespace scp::health

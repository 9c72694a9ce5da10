// test_against: the Wald statistic of another estimate against the fit, per block.
#include <gtest/gtest.h>

#include "refine/fit.hpp"

namespace scp::refine {
namespace {

FitResult a_fit() {
  FitResult r;
  r.theta << 1247, 0.8, 1813, 0.1, 0.0594, 1.1;
  r.sigma << 10, 0.01, 15, 0.001, 1e-7, 1e-7;
  r.covariance = r.sigma.cwiseAbs2().asDiagonal();
  return r;
}

TEST(BiasTest, AnAgreeingEstimateIsNotBiased) {
  const FitResult f = a_fit();
  const BiasTest t = test_against(f, f.theta + f.sigma, f.sigma);
  // d = σ per parameter, C = 2σ²: statistic = Σ 1/2 = 2 (mechanical), 1 (thermal).
  EXPECT_NEAR(t.statistic[0], 2.0, 1e-8);
  EXPECT_NEAR(t.statistic[1], 1.0, 1e-8);
  EXPECT_EQ(t.threshold[0], 18.467);
  EXPECT_EQ(t.threshold[1], 13.816);
  EXPECT_FALSE(t.biased[0]);
  EXPECT_FALSE(t.biased[1]);
}

TEST(BiasTest, TheNoisyPaperLawIsBiased) {
  // θ1..θ4 at 0.17 of the fit with a small claimed σ: the paper law under noise.
  const FitResult f = a_fit();
  Vector6 other = f.theta;
  other.head<4>() *= 0.17;
  const BiasTest t = test_against(f, other, f.sigma * 2.0);
  EXPECT_TRUE(t.biased[0]);
  EXPECT_FALSE(t.biased[1]);
  // The same bias with an honest (huge) σ is not flagged.
  Vector6 honest = f.sigma;
  honest.head<4>() = (f.theta - other).head<4>().cwiseAbs();
  EXPECT_FALSE(test_against(f, other, honest).biased[0]);
}

TEST(BiasTest, KnownParametersLeaveTheTest) {
  const FitResult f = a_fit();
  Vector6 other = f.theta;
  other[2] *= 10.0;  // known, so ignored
  std::array<bool, 6> known{};
  known[2] = true;
  known[4] = known[5] = true;
  const BiasTest t = test_against(f, other, f.sigma, known);
  EXPECT_EQ(t.threshold[0], 16.266);
  EXPECT_EQ(t.threshold[1], 0.0);
  EXPECT_FALSE(t.biased[0]);
  EXPECT_FALSE(t.biased[1]);
  Vector6 nan_theta = f.theta;
  nan_theta[0] = std::nan("");
  EXPECT_TRUE(test_against(f, nan_theta, f.sigma).biased[0]);
}

}  // namespace
}  // namespace scp::refine

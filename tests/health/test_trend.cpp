// Trends over overlapping windows: exact on a noise-free line, and an honest σ of the slope
// when the windows share their data (simulated), where treating them as independent is not.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <vector>

#include "health/covariance.hpp"
#include "health/trend.hpp"
#include "tests/health/synthetic_windows.hpp"

namespace scp::health {
namespace {

TEST(Trend, CrossCovarianceFollowsTheSharedData) {
  WindowEstimate a, b;
  a.t_begin = 0;
  a.t_end = 300;
  b.t_begin = 150;
  b.t_end = 450;
  a.covariance = b.covariance = Matrix6::Identity() * 4.0;
  EXPECT_TRUE(window_cross_covariance(a, b).isApprox(Matrix6::Identity() * 2.0));
  b.t_begin = 300;
  b.t_end = 600;
  EXPECT_TRUE(window_cross_covariance(a, b).isZero(0.0));
}

// A window of a loosely determined actuator (N3): θ1..θ4 known well except along their common
// scale, whose direction each window sees a little differently.
WindowEstimate loose_window(double t_end, const Vector6& scale_direction) {
  WindowEstimate w;
  w.t_begin = t_end - 120.0;
  w.t_end = t_end;
  w.theta = test::paper_theta();
  const Vector6 u = scale_direction.normalized();
  const Vector6 tight = (test::paper_theta() * 1e-4).cwiseAbs2();
  w.covariance = tight.asDiagonal();
  w.covariance += (0.2 * 0.2 * test::paper_theta().head<4>().squaredNorm()) * u * u.transpose();
  return w;
}

double smallest_correlation_eigenvalue(const Matrix6& c) {
  const Vector6 inverse = c.diagonal().cwiseSqrt().cwiseInverse();
  const Matrix6 r = inverse.asDiagonal() * c * inverse.asDiagonal();
  return Eigen::SelfAdjointEigenSolver<Matrix6>(r).eigenvalues().minCoeff();
}

// Two windows 30 s apart extrapolated 60 s weigh 3 and −2: with the overlap's approximate
// cross-covariance the sandwich had a negative variance there (the fast detector's prior
// precision then went indefinite and its scores were meaningless: a false alarm at N3).
TEST(Trend, AnExtrapolatedLevelOfOverlappingLooseWindowsHasAPositiveCovariance) {
  Vector6 first = test::paper_theta(), second = test::paper_theta();
  first.tail<2>().setZero();
  second.tail<2>().setZero();
  second[1] *= 1.05;
  second[2] *= 0.95;
  const std::vector<WindowEstimate> windows = {loose_window(390.0, first),
                                               loose_window(420.0, second)};
  const TrendFit fit = fit_trend(windows, 420.0, true);
  ASSERT_TRUE(fit.with_slope);
  EXPECT_GE(smallest_correlation_eigenvalue(fit.level_covariance), -1e-9);
  // Not by shrinking the windows' uncertainty: the level is at least as uncertain as either.
  for (int i = 0; i < kParams; ++i)
    EXPECT_GE(fit.level_covariance(i, i), windows[1].covariance(i, i)) << i;
}

TEST(Trend, APositiveCovarianceIsLeftAsItIsAndAKnownParameterStaysKnown) {
  Matrix6 c = test::window_covariance_300s();
  EXPECT_TRUE(positive_semidefinite(c).isApprox(c, 1e-12));
  c.row(5).setZero();
  c.col(5).setZero();
  c(0, 1) = c(1, 0) = 1.5 * std::sqrt(c(0, 0) * c(1, 1));  // a correlation beyond one
  const Matrix6 repaired = positive_semidefinite(c);
  EXPECT_EQ(repaired(5, 5), 0.0);
  EXPECT_TRUE(repaired.row(5).isZero(0.0));
  const Eigen::SelfAdjointEigenSolver<Matrix6> eig(repaired);
  EXPECT_GE(eig.eigenvalues().minCoeff(), -1e-12 * eig.eigenvalues().maxCoeff());
}

TEST(Trend, RecoversALineExactly) {
  const Vector6 theta0 = test::paper_theta();
  Vector6 slope = theta0 * 1e-4;  // per second
  std::vector<WindowEstimate> windows;
  for (double end = 300; end <= 1500; end += 10) {
    WindowEstimate w;
    w.t_begin = end - 300;
    w.t_end = end;
    w.theta = theta0 + slope * w.midpoint();
    w.covariance = test::window_covariance_300s();
    windows.push_back(w);
  }
  const TrendFit fit = fit_trend(windows, 2000.0, true);
  ASSERT_TRUE(fit.with_slope);
  for (int i = 0; i < kParams; ++i) {
    EXPECT_NEAR(fit.slope[i] / slope[i], 1.0, 1e-9) << i;
    EXPECT_NEAR(fit.level[i] / (theta0[i] + slope[i] * 2000.0), 1.0, 1e-12) << i;
  }
  const TrendFit level = fit_trend(windows, 2000.0, false);
  EXPECT_FALSE(level.with_slope);
  EXPECT_TRUE(level.slope.isZero(0.0));
}

TEST(Trend, SlopeSigmaAccountsForOverlap) {
  // 200 runs of 30 min of 300 s windows refitted every 10 s on a constant θ: the spread of the
  // fitted slopes matches the overlap-aware σ within the spread's sampling error (±10 % at
  // 2σ), while the σ of independent windows is several times too small.
  const Matrix6 c = test::window_covariance_300s();
  const int runs = 200;
  double sum_sq = 0.0, sigma = 0.0, naive = 0.0;
  for (int run = 0; run < runs; ++run) {
    test::WindowStream stream([](double) { return test::paper_theta(); }, c, 300.0, 10.0, run);
    std::vector<WindowEstimate> windows;
    for (int k = 0; k < 150; ++k) windows.push_back(stream.next());
    const TrendFit fit = fit_trend(windows, windows.back().midpoint(), true);
    sum_sq += fit.slope[4] * fit.slope[4];
    sigma += fit.slope_sigma[4];
    // Ordinary weighted least squares with independent errors: σ² = 1/Σ w x².
    double mean = 0.0;
    for (const auto& w : windows) mean += w.midpoint() / windows.size();
    double sxx = 0.0;
    for (const auto& w : windows) sxx += std::pow(w.midpoint() - mean, 2) / w.covariance(4, 4);
    naive += 1.0 / std::sqrt(sxx);
  }
  const double spread = std::sqrt(sum_sq / runs);
  EXPECT_NEAR(sigma / runs / spread, 1.0, 0.15);
  EXPECT_LT(naive / runs / spread, 0.4);
}

}  // namespace
}  // namespace scp::health

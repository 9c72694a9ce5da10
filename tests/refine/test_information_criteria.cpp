// BIC and YIC (refine/information_criteria.hpp): the deviance against a direct Gaussian
// log-likelihood, and both criteria choosing among nested least-squares models of known truth.
#include <gtest/gtest.h>

#include <Eigen/LU>
#include <Eigen/QR>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include "refine/information_criteria.hpp"

namespace scp::refine {
namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;

TEST(InformationCriteria, DevianceIsMinusTwiceTheGaussianLogLikelihood) {
  std::mt19937_64 rng(2);
  std::normal_distribution<double> g(0.0, 1.0);
  double direct = 0.0;
  std::vector<ChannelResiduals> channels;
  for (double sigma : {1e-7, 0.1}) {
    const int n = 500;
    std::vector<double> r(n);
    double rss = 0.0;
    for (double& v : r) {
      v = sigma * g(rng);
      rss += v * v;
    }
    const double var = rss / n;  // the maximizing variance
    for (double v : r) direct += std::log(2 * std::numbers::pi * var) + v * v / var;
    channels.push_back({rss, static_cast<std::size_t>(n)});
  }
  EXPECT_NEAR(gaussian_deviance(channels), direct, 1e-9 * std::abs(direct));
  EXPECT_NEAR(bic(channels, 7) - gaussian_deviance(channels), 7 * std::log(1000.0), 1e-9);
  channels.push_back({0.0, 0});  // an unmeasured channel counts nothing
  EXPECT_NEAR(gaussian_deviance(channels), direct, 1e-9 * std::abs(direct));
}

// y = 1 + 0.5 t + noise on t ∈ [0, 1] (two channels: the same design, independent noise of very
// different scales, as x and T̄ are); polynomial models of order 0..3 fitted by least squares.
struct Polynomial {
  double rss[2];
  VectorXd estimates, variances;  // of the first channel's coefficients
};

Polynomial fit_polynomial(const VectorXd& t, const VectorXd& y0, const VectorXd& y1, int order) {
  MatrixXd a(t.size(), order + 1);
  for (int j = 0; j <= order; ++j) a.col(j) = t.array().pow(j);
  const Eigen::HouseholderQR<MatrixXd> qr(a);
  Polynomial p;
  const VectorXd c0 = qr.solve(y0), c1 = qr.solve(y1);
  p.rss[0] = (y0 - a * c0).squaredNorm();
  p.rss[1] = (y1 - a * c1).squaredNorm();
  const double s2 = p.rss[0] / static_cast<double>(t.size() - order - 1);
  p.estimates = c0;
  p.variances = s2 * (a.transpose() * a).inverse().diagonal();
  return p;
}

// A channel the model reproduces exactly (RSS 0, ln 0 = −∞) or whose RSS is not finite has no
// likelihood to compare: NaN, not −∞ (whose differences would be NaN or ±∞ at random).
TEST(InformationCriteria, ANonPositiveOrNonFiniteRssIsNaN) {
  for (double bad : {0.0, -1.0, std::numeric_limits<double>::infinity(),
                     std::numeric_limits<double>::quiet_NaN()}) {
    const std::vector<ChannelResiduals> channels{{1e-9, 100}, {bad, 100}};
    EXPECT_TRUE(std::isnan(gaussian_deviance(channels))) << bad;
    EXPECT_TRUE(std::isnan(bic(channels, 3))) << bad;
  }
  const std::vector<ChannelResiduals> unmeasured{{1e-9, 100}, {0.0, 0}};
  EXPECT_TRUE(std::isfinite(bic(unmeasured, 3)));
}

TEST(InformationCriteria, BicChoosesTheTrueOrderAndRarelyAnExtraTerm) {
  const int n = 400, seeds = 40;
  std::normal_distribution<double> g(0.0, 1.0);
  int right = 0, extended = 0;
  for (int seed = 1; seed <= seeds; ++seed) {
    std::mt19937_64 rng(seed);
    VectorXd t(n), y0(n), y1(n);
    for (int k = 0; k < n; ++k) {
      t[k] = static_cast<double>(k) / n;
      y0[k] = 1.0 + 0.5 * t[k] + 0.1 * g(rng);
      y1[k] = 40.0 - 3.0 * t[k] + 1e-3 * g(rng);
    }
    int best = -1;
    double best_bic = 0.0;
    for (int order = 0; order <= 3; ++order) {
      const Polynomial p = fit_polynomial(t, y0, y1, order);
      const ChannelResiduals ch[2] = {{p.rss[0], static_cast<std::size_t>(n)},
                                      {p.rss[1], static_cast<std::size_t>(n)}};
      // Both channels' coefficients and their two variances.
      const double b = bic(ch, 2 * (order + 1) + 2);
      if (best < 0 || b < best_bic) {
        best = order;
        best_bic = b;
      }
    }
    right += best == 1 ? 1 : 0;
    extended += best > 1 ? 1 : 0;
  }
  // An extra coefficient per channel enters when χ²₂ > 2 ln(800) = 13.4: 1e-3 per seed.
  EXPECT_GE(right, seeds - 1);
  EXPECT_LE(extended, 1);
}

TEST(InformationCriteria, YicPenalizesATermTheDataCannotDetermine) {
  // On t ∈ [0, 0.05] a cubic term is barely distinguishable from the lower ones: its estimate's
  // relative variance is huge, so YIC rises although the residual falls.
  const int n = 400;
  std::mt19937_64 rng(7);
  std::normal_distribution<double> g(0.0, 1.0);
  VectorXd t(n), y(n);
  for (int k = 0; k < n; ++k) {
    t[k] = 0.05 * k / n;
    y[k] = 1.0 + 20.0 * t[k] + 0.01 * g(rng);
  }
  const VectorXd unused = VectorXd::Zero(n);
  const Polynomial line = fit_polynomial(t, y, unused, 1);
  const Polynomial cubic = fit_polynomial(t, y, unused, 3);
  const double var_y = (y.array() - y.mean()).square().mean();
  const double yic_line =
      yic(line.rss[0] / n, var_y, {line.estimates.data(), 2}, {line.variances.data(), 2});
  const double yic_cubic =
      yic(cubic.rss[0] / n, var_y, {cubic.estimates.data(), 4}, {cubic.variances.data(), 4});
  EXPECT_LT(cubic.rss[0], line.rss[0]);
  EXPECT_LT(yic_line, yic_cubic);
  EXPECT_LT(yic_line, -10.0);  // a well-determined model is strongly negative
  EXPECT_TRUE(std::isnan(yic(1.0, 1.0, {}, {})));
  const double zero = 0.0, one = 1.0;
  EXPECT_TRUE(std::isnan(yic(1.0, 1.0, {&zero, 1}, {&one, 1})));
}

}  // namespace
}  // namespace scp::refine

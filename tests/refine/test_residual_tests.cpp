// The statistics under refine/validation.hpp on inputs whose answer is known: tail probabilities
// against closed forms and tables, block means against direct sums, and the regression and
// whiteness tests' false-alarm rates and power over many random draws.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <Eigen/QR>
#include <cmath>
#include <random>
#include <vector>

#include "refine/block_means.hpp"
#include "refine/probability.hpp"
#include "refine/residual_tests.hpp"

namespace scp::refine {
namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;

TEST(Probability, ChiSquareMatchesItsClosedForms) {
  for (double x : {0.1, 0.5, 3.0, 20.0, 100.0, 700.0}) {
    // Two degrees of freedom: an exponential; one: a two-sided normal tail.
    EXPECT_NEAR(chi_square_survival(x, 2.0) / std::exp(-0.5 * x), 1.0, 1e-12) << x;
    EXPECT_NEAR(chi_square_survival(x, 1.0) / std::erfc(std::sqrt(0.5 * x)), 1.0, 1e-10) << x;
  }
  EXPECT_EQ(chi_square_survival(0.0, 3.0), 1.0);
  EXPECT_EQ(chi_square_survival(-1.0, 3.0), 1.0);
  EXPECT_TRUE(std::isnan(chi_square_survival(1.0, 0.0)));
}

TEST(Probability, ChiSquareMatchesTheTables) {
  // 99 % points.
  EXPECT_NEAR(chi_square_survival(6.634897, 1), 0.01, 1e-7);
  EXPECT_NEAR(chi_square_survival(23.209251, 10), 0.01, 1e-7);
  EXPECT_NEAR(chi_square_survival(31.999927, 16), 0.01, 1e-7);
  EXPECT_NEAR(chi_square_survival(3.940299, 10), 0.95, 1e-7);  // the lower 5 %
  // A 300 s window's noise-ratio test: ν ≈ 3e5, where Wilson–Hilferty is exact to ~1e-5.
  const double nu = 299990.0, z = 2.326347874, a = 2.0 / (9.0 * nu);
  const double x99 = nu * std::pow(1.0 - a + z * std::sqrt(a), 3);
  EXPECT_NEAR(chi_square_survival(x99, nu), 0.01, 1e-4);
}

TEST(Probability, FMatchesTheTablesAndItsLimits) {
  // F(1, ν) is t²: t_{0.995}(30) = 2.749996.
  EXPECT_NEAR(f_survival(2.749996 * 2.749996, 1, 30), 0.01, 1e-6);
  // F_{0.99}(5, 100) = 3.2059 and F_{0.95}(5, 100) = 2.3053 (four decimals in the tables).
  EXPECT_NEAR(f_survival(3.2059, 5, 100), 0.01, 2e-5);
  EXPECT_NEAR(f_survival(2.3053, 5, 100), 0.05, 2e-5);
  // d2 → ∞: χ²(d1)/d1.
  for (double x : {1.0, 5.0, 15.0})
    EXPECT_NEAR(f_survival(x / 5.0, 5, 1e9), chi_square_survival(x, 5), 1e-6) << x;
  // Far tails stay positive and ordered.
  EXPECT_GT(f_survival(400.0, 1, 200), 0.0);
  EXPECT_LT(f_survival(400.0, 1, 200), f_survival(300.0, 1, 200));
  EXPECT_EQ(f_survival(0.0, 2, 3), 1.0);
}

TEST(Probability, SidakKeepsTheFamilyLevel) {
  for (int n : {1, 2, 6, 8}) {
    const double a = sidak_level(0.01, n);
    EXPECT_NEAR(1.0 - std::pow(1.0 - a, n), 0.01, 1e-15) << n;
  }
}

TEST(BlockMeans, MeansAndCountsAreTheBlocksOwn) {
  BlockMeans store(0.5, 2, 100);
  for (int k = 0; k < 1000; ++k) {
    const double t = 10.0 + 0.01 * k;  // 50 samples per block, 20 blocks
    double* s = store.accumulate(t);
    s[0] += t;
    s[1] += 1.0;
  }
  const MatrixXd m = store.means();
  const VectorXd c = store.counts();
  ASSERT_EQ(m.rows(), 20);
  for (int b = 0; b < 20; ++b) {
    EXPECT_EQ(c[b], 50.0);
    EXPECT_NEAR(m(b, 0), 10.0 + 0.5 * b + 0.245, 1e-9);
    EXPECT_EQ(m(b, 1), 1.0);
  }
}

TEST(BlockMeans, AFullStoreMergesPairsAndKeepsEverySample) {
  // 100 s at 10 Hz into 1 s blocks, room for 8: the blocks double to 16 s (7 of them).
  BlockMeans store(1.0, 1, 8);
  double total = 0.0;
  for (int k = 0; k < 1000; ++k) {
    const double t = 0.1 * k;
    store.accumulate(t)[0] += t;
    total += t;
  }
  EXPECT_EQ(store.block_s(), 16.0);
  const MatrixXd m = store.means();
  const VectorXd c = store.counts();
  ASSERT_EQ(m.rows(), 7);
  EXPECT_EQ(c.sum(), 1000.0);
  EXPECT_NEAR(m.col(0).dot(c), total, 1e-6);
  for (int b = 0; b < 6; ++b) {
    EXPECT_EQ(c[b], 160.0) << b;
    EXPECT_NEAR(m(b, 0), 16.0 * b + 7.95, 1e-9) << b;
  }
}

TEST(BlockMeans, BlocksShorterThanTheSamplesSpacingMergeUntilThereIsRoom) {
  // Samples 1 s apart into 0.4 s blocks, room for 4: the indices 0, 2, 5, 7 of a full store
  // halve to 0, 1, 2, 3, which one merge of pairs does not join (it wrote past the store: a
  // crash of the daemon when a fitted model's time constant set a block below 1 ms).
  BlockMeans store(0.4, 1, 4);
  double total = 0.0;
  for (int k = 0; k < 40; ++k) {
    store.accumulate(k)[0] += k;
    total += k;
  }
  const MatrixXd m = store.means();
  const VectorXd c = store.counts();
  ASSERT_LE(c.size(), 5);
  EXPECT_EQ(c.sum(), 40.0);
  EXPECT_NEAR(m.col(0).dot(c), total, 1e-9);
  EXPECT_GE(store.block_s(), 1.6);
}

TEST(BlockMeans, AGapLeavesNoEmptyBlock) {
  BlockMeans store(1.0, 1, 16);
  for (double t : {0.0, 0.5, 5.2, 5.7, 6.1}) store.accumulate(t)[0] += t;
  const VectorXd c = store.counts();
  ASSERT_EQ(c.size(), 3);
  EXPECT_EQ(c[0], 2.0);
  EXPECT_EQ(c[1], 2.0);
  EXPECT_EQ(c[2], 1.0);
}

// accumulate() keeps a sample that is not past the open block's end in that block without
// computing its index: the blocks must still be the ones floor((t − t0)/block) names, for samples
// a few ulps either side of every edge and for a clock that counts from the epoch.
TEST(BlockMeans, ASampleOnEitherSideOfAnEdgeIsInTheBlockItsIndexNames) {
  for (const double t0 : {0.0, 12.5, 1.7e9}) {
    const double block = 0.1;
    BlockMeans store(block, 1, 1000);
    std::vector<long> expected_counts;
    long previous_index = -1;
    const auto add = [&](double t) {
      store.accumulate(t)[0] += 1.0;
      const long index = static_cast<long>(std::floor((t - t0) / block));
      if (index != previous_index) expected_counts.push_back(0);
      ++expected_counts.back();
      previous_index = index;
    };
    add(t0);
    for (int edge = 1; edge <= 20; ++edge) {
      const double at = t0 + edge * block;
      // The representable instants nearest the edge, in order.
      double before = at;
      for (int i = 0; i < 3; ++i) before = std::nextafter(before, -1.0);
      for (double t = before; t <= at + 4.0 * (at - before); t = std::nextafter(t, 2.0 * at + 1.0))
        add(t);
      add(at + 0.5 * block);
    }
    const VectorXd c = store.counts();
    ASSERT_EQ(c.size(), static_cast<Eigen::Index>(expected_counts.size())) << t0;
    for (Eigen::Index b = 0; b < c.size(); ++b)
      EXPECT_EQ(c[b], static_cast<double>(expected_counts[static_cast<std::size_t>(b)]))
          << "t0 " << t0 << " block " << b;
  }
}

// A regression design of M rows: X the fit's span (a constant and a slow sine), Z two candidates
// that are neither in it nor orthogonal to it.
struct Design {
  MatrixXd x, z;
  explicit Design(int m) : x(m, 2), z(m, 2) {
    for (int b = 0; b < m; ++b) {
      const double s = static_cast<double>(b) / m;
      x(b, 0) = 1.0;
      x(b, 1) = std::sin(6.0 * s);
      z(b, 0) = std::cos(4.0 * s) + 0.3 * std::sin(6.0 * s);
      z(b, 1) = s * s;
    }
  }
};

// AR(1) noise of unit innovation (ρ = 0: white).
VectorXd ar1_noise(int m, double rho, std::mt19937_64& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  VectorXd e(m);
  double state = g(rng) / std::sqrt(1.0 - rho * rho);
  for (int b = 0; b < m; ++b) {
    state = rho * state + g(rng);
    e[b] = state;
  }
  return e;
}

double rejection_rate(double rho, double level, int draws) {
  const int m = 120;
  const Design d(m);
  std::mt19937_64 rng(11);
  int rejected = 0;
  for (int i = 0; i < draws; ++i) {
    const VectorXd y = d.x * Eigen::Vector2d(2.0, -1.0) + ar1_noise(m, rho, rng);
    const NestedTestResult r = nested_f_test(y, d.x, d.z, VectorXd::Ones(m));
    EXPECT_TRUE(r.performed);
    EXPECT_EQ(r.dof1, 2);
    EXPECT_TRUE(r.dof2 == m - 4 || r.dof2 == m - 4 - 1) << r.dof2;  // plain or prewhitened
    rejected += r.p_value < level ? 1 : 0;
  }
  return static_cast<double>(rejected) / draws;
}

TEST(NestedFTest, FalseAlarmsAtTheLevelOnWhiteNoise) {
  // 3000 draws: the binomial sd of a 5 % rate is 0.4 %, of a 1 % rate 0.18 %.
  const double at5 = rejection_rate(0.0, 0.05, 3000);
  const double at1 = rejection_rate(0.0, 0.01, 3000);
  std::printf("white: %.4f at 0.05, %.4f at 0.01\n", at5, at1);
  EXPECT_NEAR(at5, 0.05, 0.013);
  EXPECT_NEAR(at1, 0.01, 0.006);
}

TEST(NestedFTest, ColouredNoiseDoesNotReadAsDependence) {
  // Block means of a slow sensor drift: AR(1) with ρ = 0.7. The plain test alone picks the colour
  // up as a dependence on slow candidates (39 % rejections at 5 % on 140 rows of similar
  // regressors, docs/validation.md); with the prewhitened one beside it, about twice the level.
  const double at5 = rejection_rate(0.7, 0.05, 2000);
  std::printf("AR(1) 0.7: %.4f at 0.05\n", at5);
  EXPECT_LT(at5, 0.12);
}

TEST(NestedFTest, FindsTheCandidateAndItsSize) {
  const int m = 120;
  const Design d(m);
  std::mt19937_64 rng(3);
  const VectorXd y =
      d.x * Eigen::Vector2d(2.0, -1.0) + 0.8 * d.z.col(0) + 0.05 * ar1_noise(m, 0.0, rng);
  const NestedTestResult r = nested_f_test(y, d.x, d.z.col(0), VectorXd::Ones(m));
  ASSERT_TRUE(r.performed);
  EXPECT_LT(r.p_value, 1e-10);
  EXPECT_NEAR(r.coefficients[0], 0.8, 0.03);
  EXPECT_GT(r.explained, 0.9);
}

TEST(NestedFTest, ACandidateTheFitAlreadySpansIsNotATest) {
  const int m = 60;
  const Design d(m);
  const VectorXd y = VectorXd::LinSpaced(m, 0.0, 1.0).array().sin();
  const MatrixXd in_span = 3.0 * d.x.col(0) - 2.0 * d.x.col(1);
  const NestedTestResult r = nested_f_test(y, d.x, in_span, VectorXd::Ones(m));
  EXPECT_FALSE(r.performed);
  EXPECT_EQ(r.dof1, 0);
}

TEST(LjungBox, FalseAlarmsAtTheLevelAndSeesColour) {
  std::mt19937_64 rng(5);
  int white = 0, coloured = 0;
  const int draws = 2000;
  for (int i = 0; i < draws; ++i) {
    white += ljung_box(ar1_noise(200, 0.0, rng), 10).p_value < 0.05 ? 1 : 0;
    coloured += ljung_box(ar1_noise(200, 0.4, rng), 10).p_value < 0.05 ? 1 : 0;
  }
  std::printf("Ljung-Box at 0.05: white %.4f, AR(1) 0.4 %.4f\n", 1.0 * white / draws,
              1.0 * coloured / draws);
  EXPECT_NEAR(1.0 * white / draws, 0.05, 0.015);
  EXPECT_GT(1.0 * coloured / draws, 0.9);
  EXPECT_EQ(ljung_box(VectorXd::Ones(3), 5).lags, 0);  // too short for its lags
}

// Regressors of local reach, as the placed switches' phases are at the thermal block's layout: a
// step decaying over `decay` rows from every `spacing`-th row, beside a constant.
MatrixXd local_regressors(int m, int spacing, double decay) {
  const int columns = m / spacing;
  MatrixXd x = MatrixXd::Zero(m, columns + 1);
  x.col(columns).setOnes();
  for (int j = 0; j < columns; ++j)
    for (int b = j * spacing; b < m; ++b) x(b, j) = std::exp(-(b - j * spacing) / decay);
  return x;
}

struct SerialRates {
  double ljung_box = 0.0, recursive = 0.0;
};

// Rejections at `level` of the residual of y = X·1 + AR(1) noise on local regressors.
SerialRates serial_rejections(double rho, double level, int draws) {
  const int m = 480, lags = 16;
  const MatrixXd x = local_regressors(m, 3, 8.0);
  const Eigen::ColPivHouseholderQR<MatrixXd> qr(x);
  std::mt19937_64 rng(17);
  SerialRates rates;
  for (int i = 0; i < draws; ++i) {
    const VectorXd y = x * VectorXd::Ones(x.cols()) + ar1_noise(m, rho, rng);
    const VectorXd u = y - x * qr.solve(y);
    rates.ljung_box += ljung_box(u, lags).p_value < level ? 1.0 : 0.0;
    const VectorXd w = recursive_residuals(y, x, VectorXd::Ones(m));
    EXPECT_EQ(w.size(), m - x.cols());
    rates.recursive += ljung_box(w, lags).p_value < level ? 1.0 : 0.0;
  }
  rates.ljung_box /= draws;
  rates.recursive /= draws;
  return rates;
}

TEST(RecursiveResiduals, FalseAlarmsAtTheLevelWhereLocalRegressorsBiasLjungBox) {
  // A third of the rows spent on regressors of local reach: the fit's residuals are negatively
  // correlated at short lags, which Ljung–Box reads as colour; the recursive residuals are not.
  const SerialRates white = serial_rejections(0.0, 0.05, 1000);
  std::printf("white at 0.05: Ljung-Box on the residuals %.4f, on the recursive ones %.4f\n",
              white.ljung_box, white.recursive);
  EXPECT_GT(white.ljung_box, 0.5);
  EXPECT_NEAR(white.recursive, 0.05, 0.02);
}

TEST(RecursiveResiduals, SeeColourBeyondTheRegressors) {
  // Regressors of local reach explain much of a colour on their own time scale (AR(1) 0.8 about
  // 3 rows per regressor, each decaying over 8): what they leave is what any test can see.
  const SerialRates coloured = serial_rejections(0.8, 0.05, 200);
  std::printf("AR(1) 0.8 at 0.05: Ljung-Box on the recursive residuals %.4f\n", coloured.recursive);
  EXPECT_GT(coloured.recursive, 0.25);
}

TEST(RecursiveResiduals, AreThePredictionErrorsOfTheRowsBefore) {
  // Row b's, by direct least squares on rows 0..b−1.
  const int m = 12;
  MatrixXd x(m, 2);
  VectorXd y(m), weights(m);
  for (int b = 0; b < m; ++b) {
    x(b, 0) = 1.0;
    x(b, 1) = std::sin(0.7 * b);
    y[b] = std::cos(1.3 * b) + 0.1 * b;
    weights[b] = 1.0 + (b % 3);
  }
  const VectorXd w = recursive_residuals(y, x, weights);
  ASSERT_EQ(w.size(), m - 2);
  const VectorXd root = weights.cwiseSqrt();
  const MatrixXd xw = root.asDiagonal() * x;
  const VectorXd yw = root.asDiagonal() * y;
  for (int b = 2; b < m; ++b) {
    const MatrixXd before = xw.topRows(b);
    const Eigen::Matrix2d info = before.transpose() * before;
    const Eigen::Vector2d beta = info.ldlt().solve(before.transpose() * yw.head(b));
    const Eigen::RowVector2d row = xw.row(b);
    const double expected =
        (yw[b] - row.dot(beta)) / std::sqrt(1.0 + row * info.inverse() * row.transpose());
    EXPECT_NEAR(std::abs(w[b - 2]), std::abs(expected), 1e-12) << b;
  }
}

}  // namespace
}  // namespace scp::refine

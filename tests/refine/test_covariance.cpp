// The covariance helpers of refine/covariance.hpp on inputs whose answer is known.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <random>
#include <vector>

#include "refine/covariance.hpp"

namespace scp::refine {
namespace {

TEST(Covariance, ChiSquareQuantileMatchesTheTables) {
  // χ²_ν(0.99) from the tables, divided by ν.
  EXPECT_NEAR(chi_square_99_over_dof(19), 36.1909 / 19, 0.005 * 36.1909 / 19);
  EXPECT_NEAR(chi_square_99_over_dof(9), 21.6660 / 9, 0.005 * 21.6660 / 9);
  EXPECT_NEAR(chi_square_99_over_dof(3), 11.3449 / 3, 0.01 * 11.3449 / 3);
}

// Linear regression y_k = φ_kᵀβ + e_k with white unit noise over 20 batches: the score sums and
// information the pass would accumulate, at the least-squares β̂.
struct Regression {
  ParamMatrix normal = ParamMatrix::Zero();
  std::vector<ParamVector> scores;
  std::vector<ParamMatrix> information;
};

Regression regression(unsigned seed, double slow_noise) {
  constexpr int kBatches = 20, kPerBatch = 500;
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> gauss(0.0, 1.0);
  std::vector<ParamVector> phi;
  std::vector<double> y;
  double slow = 0.0;
  for (int k = 0; k < kBatches * kPerBatch; ++k) {
    ParamVector f;
    const double t = k / 1000.0;
    for (int j = 0; j < kParams; ++j) f[j] = std::sin((j + 1) * 0.7 * t + j);  // unequal batches
    phi.push_back(f);
    slow = 0.998 * slow + std::sqrt(1 - 0.998 * 0.998) * gauss(rng);  // 500-sample correlation
    y.push_back(gauss(rng) + slow_noise * slow);
  }
  Regression r;
  ParamVector rhs = ParamVector::Zero();
  for (std::size_t k = 0; k < phi.size(); ++k) {
    r.normal += phi[k] * phi[k].transpose();
    rhs += phi[k] * y[k];
  }
  const ParamVector beta = r.normal.ldlt().solve(rhs);
  r.scores.assign(kBatches, ParamVector::Zero());
  r.information.assign(kBatches, ParamMatrix::Zero());
  for (std::size_t k = 0; k < phi.size(); ++k) {
    const std::size_t b = k / kPerBatch;
    r.scores[b] += phi[k] * (y[k] - phi[k].dot(beta));
    r.information[b] += phi[k] * phi[k].transpose();
  }
  return r;
}

TEST(Covariance, BatchMeansAgreeWithTheCovarianceOnWhiteNoise) {
  FreeMask free{};
  free.fill(true);
  double mean_ratio = 0.0;
  int scaled = 0, count = 0;
  for (unsigned seed = 1; seed <= 40; ++seed) {
    const Regression r = regression(seed, 0.0);
    ParamMatrix covariance;
    ASSERT_TRUE(inverse_on_free(r.normal, free, covariance));
    const BatchMeansCheck check =
        check_against_batch_means(covariance, r.normal, r.scores, r.information, free);
    for (int i = 0; i < kParams; ++i) {
      EXPECT_GT(check.dof[i], 3.0);
      EXPECT_LT(check.dof[i], 19.0);  // fewer than the batches: the projection and their weights
      mean_ratio += check.ratio[i];
      scaled += check.factor[i] > 1.0 ? 1 : 0;
      ++count;
    }
  }
  mean_ratio /= count;
  std::printf("white: mean batch-means / covariance %.3f, %d of %d scaled\n", mean_ratio, scaled,
              count);
  EXPECT_NEAR(mean_ratio, 1.0, 0.1);  // the projection's loss corrected
  EXPECT_LE(scaled, 12);              // 1 % expected: 3.6 of 360
}

TEST(Covariance, BatchMeansScaleTheSigmasASlowNoiseHides) {
  FreeMask free{};
  free.fill(true);
  double mean_factor = 0.0;
  for (unsigned seed = 1; seed <= 10; ++seed) {
    const Regression r = regression(seed, 0.5);
    ParamMatrix covariance;
    ASSERT_TRUE(inverse_on_free(r.normal, free, covariance));
    const ParamMatrix before = covariance;
    const BatchMeansCheck check =
        check_against_batch_means(covariance, r.normal, r.scores, r.information, free);
    for (int i = 0; i < kParams; ++i) {
      EXPECT_NEAR(covariance(i, i), before(i, i) * check.factor[i] * check.factor[i],
                  1e-12 * before(i, i));
      if (check.factor[i] > 1.0) {
        EXPECT_NEAR(check.factor[i] * check.factor[i], check.ratio[i], 1e-9);
      }
      mean_factor += check.factor[i] / (10 * kParams);
    }
  }
  // The slow part's long-run variance is 0.25·(1 + ρ)/(1 − ρ) ≈ 250× the white one per sample:
  // σ is ~16× too small without the check.
  std::printf("slow: mean factor %.2f\n", mean_factor);
  EXPECT_GT(mean_factor, 5.0);
}

TEST(Covariance, FewerThanTwoBatchesLeaveTheCovarianceAlone) {
  ParamMatrix covariance = ParamMatrix::Identity();
  const std::vector<ParamVector> scores(1, ParamVector::Ones() * 100.0);
  const std::vector<ParamMatrix> information(1, ParamMatrix::Identity());
  FreeMask free{};
  free.fill(true);
  const BatchMeansCheck check =
      check_against_batch_means(covariance, ParamMatrix::Identity(), scores, information, free);
  EXPECT_EQ(check.factor, ParamVector::Ones());
  EXPECT_EQ(covariance, ParamMatrix::Identity());
}

}  // namespace
}  // namespace scp::refine

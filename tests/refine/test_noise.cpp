// Under sensor noise the fit's errors must be what its σ says: seed-to-seed scatter against the
// claimed σ and the Cramér–Rao bound, on white and on coloured noise. Seeds are fixed, so each
// test is deterministic; the tolerances are wide enough for the sampling spread of 8–10 seeds and
// narrow enough that a σ off by 2× fails.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <vector>

#include "refine/fit.hpp"
#include "tests/refine/record.hpp"

namespace scp::refine {
namespace {

struct Scatter {
  double rms_z = 0.0;        // RMS over seeds and parameters of (θ̂ − θ)/σ̂
  double coverage = 0.0;     // fraction with |θ̂ − θ| ≤ 2σ̂
  double rms_z_white = 0.0;  // the same with the white-noise σ
  double coverage_white = 0.0;
  double mean_inflation = 0.0;  // FitResult::sigma_inflation over seeds and parameters
  Vector6 rms_rel_error = Vector6::Zero();
  Vector6 mean_rel_sigma = Vector6::Zero();
  int converged = 0;
};

Scatter scatter(const std::vector<WindowSample>& clean, test::Noise noise, int seeds,
                const Vector6& truth) {
  Scatter s;
  int count = 0;
  for (int seed = 1; seed <= seeds; ++seed) {
    noise.seed = static_cast<unsigned>(seed);
    const auto w = test::with_noise(clean, noise);
    Vector6 start = truth;
    start.head<4>() *= 0.17;  // the paper law's biased estimate under noise
    const FitResult r = fit(w, start);
    s.converged += r.converged ? 1 : 0;
    for (int i = 0; i < 6; ++i) {
      const double e = r.theta[i] - truth[i];
      const double z = e / r.sigma[i], zw = e / r.sigma_white[i];
      s.rms_z += z * z;
      s.rms_z_white += zw * zw;
      s.coverage += std::abs(z) <= 2.0 ? 1 : 0;
      s.coverage_white += std::abs(zw) <= 2.0 ? 1 : 0;
      s.mean_inflation += r.sigma_inflation[i];
      s.rms_rel_error[i] += (e / truth[i]) * (e / truth[i]);
      s.mean_rel_sigma[i] += r.sigma[i] / std::abs(truth[i]);
      ++count;
    }
  }
  s.rms_z = std::sqrt(s.rms_z / count);
  s.rms_z_white = std::sqrt(s.rms_z_white / count);
  s.coverage /= count;
  s.coverage_white /= count;
  s.mean_inflation /= count;
  s.rms_rel_error = (s.rms_rel_error / seeds).cwiseSqrt();
  s.mean_rel_sigma /= seeds;
  return s;
}

void print(const char* name, const Scatter& s) {
  std::printf(
      "%s: converged %d, RMS z %.2f (white σ %.2f), 2σ coverage %.0f %% (white %.0f %%), batch "
      "means scaled σ by %.2f on average\n",
      name, s.converged, s.rms_z, s.rms_z_white, 100 * s.coverage, 100 * s.coverage_white,
      s.mean_inflation);
  std::printf("  RMS rel error:");
  for (int i = 0; i < 6; ++i) std::printf(" %.2e", s.rms_rel_error[i]);
  std::printf("\n  mean rel σ:   ");
  for (int i = 0; i < 6; ++i) std::printf(" %.2e", s.mean_rel_sigma[i]);
  std::printf("\n");
}

class Noisy : public ::testing::Test {
 protected:
  const std::vector<WindowSample>* clean_ = &test::cached_paper_record(60.0);
  const Vector6 truth_ = test::theta_of(test::paper_actuator());
};

constexpr int kSeeds = 10;

TEST_F(Noisy, ErrorsMatchSigmaAtN1) {
  const Scatter s = scatter(*clean_, {.x = 1e-7, .tbar = 1e-3}, kSeeds, truth_);
  print("N1, 60 s", s);
  EXPECT_EQ(s.converged, kSeeds);
  EXPECT_GT(s.rms_z, 0.6);
  EXPECT_LT(s.rms_z, 1.6);
  EXPECT_GE(s.coverage, 0.8);
  // On white noise the Newey–West σ must not be inflated over the white one.
  EXPECT_NEAR(s.rms_z_white / s.rms_z, 1.0, 0.1);
}

// At N2 a 60 s window leaves θ1..θ4 ~45 % uncertain, where the fit is no longer linear in the
// noise; the paper's 300 s (σ ≈ 7.6 %) is where the targets are set.
TEST_F(Noisy, ErrorsMatchSigmaAtN2) {
  const Scatter s =
      scatter(test::cached_paper_record(300.0), {.x = 1e-6, .tbar = 1e-2}, kSeeds / 2, truth_);
  print("N2, 300 s", s);
  EXPECT_EQ(s.converged, kSeeds / 2);
  EXPECT_GT(s.rms_z, 0.6);
  EXPECT_LT(s.rms_z, 1.6);
  EXPECT_GE(s.coverage, 0.8);
}

// x noise through a first-order low-pass with a 10-sample correlation time: neighbouring
// residuals repeat each other, the white σ claims ~4× too much precision on θ1..θ4; the
// Newey–West σ must stay honest.
TEST_F(Noisy, NeweyWestSigmaIsHonestOnColouredNoise) {
  const Scatter s =
      scatter(*clean_, {.x = 1e-7, .tbar = 1e-3, .x_correlation_samples = 10.0}, kSeeds, truth_);
  print("N1 with x noise correlated over 10 samples, 60 s", s);
  EXPECT_EQ(s.converged, kSeeds);
  EXPECT_GT(s.rms_z, 0.6);
  EXPECT_LT(s.rms_z, 1.6);
  EXPECT_GE(s.coverage, 0.8);
  EXPECT_GT(s.rms_z_white, 2.0);  // the white covariance is dishonest here
}

// Beside white x noise a slow component (correlated over 300 samples, half the white one's
// standard deviation): the residuals' lag-one correlation is only ~0.2, so Newey–West takes ~25
// lags and sees a tenth of the slow part's long-run variance; 20 batches of 3 s see most of it.
TEST_F(Noisy, BatchMeansCatchANoiseTooSlowForNeweyWest) {
  const Scatter s = scatter(
      *clean_, {.x = 1e-7, .tbar = 1e-3, .x_slow = 0.5e-7, .x_slow_correlation_samples = 300.0},
      kSeeds, truth_);
  print("N1 with a slow x noise beside the white one, 60 s", s);
  EXPECT_EQ(s.converged, kSeeds);
  EXPECT_GT(s.rms_z, 0.6);
  EXPECT_LT(s.rms_z, 1.6);
  EXPECT_GE(s.coverage, 0.8);
  EXPECT_GT(s.mean_inflation, 1.5);
}

TEST_F(Noisy, SigmaMatchesTheCramerRaoBoundAndNoiseIsEstimated) {
  const test::Noise n1{.x = 1e-7, .tbar = 1e-3, .seed = 3};
  const auto w = test::with_noise(*clean_, n1);
  const FitResult r = fit(w, truth_);
  ASSERT_TRUE(r.converged) << r.message;
  const Matrix6 crb = cramer_rao_bound(w, truth_, InitialState::Zero(), Vector2(1e-7, 1e-3));
  for (int i = 0; i < 6; ++i) {
    const double bound = std::sqrt(crb(i, i));
    EXPECT_NEAR(r.sigma_white[i] / bound, 1.0, 0.05) << i;
    // Newey–West's σ, before the batch-means check: this seed's batch means lie at the 99.6th
    // percentile for θ1..θ4 (ratio 2.45 against ν = 14: the check scales them by 1.57, which a
    // 1 % test does to one white-noise window in a hundred).
    EXPECT_NEAR(r.sigma[i] / r.sigma_inflation[i] / bound, 1.0, 0.15) << i;
  }
  EXPECT_NEAR(r.noise_sigma[0] / 1e-7, 1.0, 0.02);
  EXPECT_NEAR(r.noise_sigma[1] / 1e-3, 1.0, 0.02);
}

}  // namespace
}  // namespace scp::refine

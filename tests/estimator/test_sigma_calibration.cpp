// σ of the paper's law under sensor noise (estimator/sigma_calibration.hpp): the calibration
// itself on a process of known variance, and the published σ of θ̂5, θ̂6 against their actual
// error on noisy simulated data.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "estimator/estimator.hpp"
#include "estimator/sigma_calibration.hpp"
#include "tests/estimator/test_plant.hpp"

namespace scp::estimator {
namespace {

// An Ornstein–Uhlenbeck process of time constant 1/λ and standard deviation s, sampled at h,
// exactly (AR(1) with ρ = e^{−λh}), beside a constant "uncalibrated" variance raw.
double calibrated_factor(double lambda, double s, double raw, double seconds, std::uint64_t seed) {
  SigmaCalibration<1> cal(lambda);
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n01;
  const double h = 1e-3, rho = std::exp(-lambda * h), q = s * std::sqrt(1.0 - rho * rho);
  double x = s * n01(rng);
  const auto steps = static_cast<std::int64_t>(seconds / h);
  for (std::int64_t k = 0; k < steps; ++k) {
    x = rho * x + q * n01(rng);
    cal.step(Eigen::Matrix<double, 1, 1>(1e6 + x), Eigen::Matrix<double, 1, 1>(raw), h);
  }
  return cal.factor()(0);
}

TEST(SigmaCalibration, RecoversTheVarianceOfAnOuProcess) {
  // 9 blocks of 20 s: the median ratio's relative sd is ~0.4·sqrt(1/16) ≈ 0.1 per seed; the mean
  // over 6 seeds is held to 15 %. Around an offset of 1e6 (shifted sums: no cancellation).
  double sum = 0.0;
  for (std::uint64_t seed = 1; seed <= 6; ++seed) {
    const double f = calibrated_factor(0.8, 1e-3, 1e-2, 200.0, seed);
    EXPECT_GT(f, 1e-4 * 0.6) << seed;
    EXPECT_LT(f, 1e-4 * 1.6) << seed;
    sum += f;
  }
  EXPECT_NEAR(sum / 6.0 / 1e-4, 1.0, 0.15);
}

TEST(SigmaCalibration, NotReadyBeforeThreeBlocks) {
  SigmaCalibration<1> cal(0.8);
  EXPECT_FALSE(cal.ready());
  const Eigen::Matrix<double, 1, 1> one(1.0);
  for (int k = 0; k < 59999; ++k) cal.step(one, one, 1e-3);  // just under 3 blocks of 20 s
  EXPECT_FALSE(cal.ready());
  cal.step(one, one, 1e-3);
  cal.step(one, one, 1e-3);
  EXPECT_TRUE(cal.ready());
  EXPECT_EQ(cal.factor()(0), 0.0);  // a constant ϑ̂ does not fluctuate
}

// The paper's experiment (Table I, four sines, β 3, λP 0.8, scaled θ) with Gaussian noise of
// 0.01 °C on T only (issue 8, N2's thermocouple-free level). The thermal error is then the noise's;
// its uncalibrated σ was 130–260× too large (bench/montecarlo.md). From 100 s on, every 7.919 s
// (~6 forgetting time constants apart: nearly independent; not a multiple of the 0.1 Hz sine's
// period, whose phase would otherwise be the same at every check: at 10 s spacing the ratios
// are 0.73 and 0.73 (with σ's profile P_ii instead of (P R₂ P)_ii they were 0.77 and 0.44)) the
// error of θ̂5, θ̂6 is compared with the published σ over three seeds: 2σ must cover the truth within
// the 99 % binomial interval of 95.4 % and RMS error / mean σ must lie in 0.6–1.6 (issue 8, "Done
// when"). Measured: 76/78 and 77/78, 1.06 and 1.04.
TEST(SigmaCalibration, ThermalSigmaTellsTheTruthUnderTemperatureNoise) {
  const test::PlantParams p;
  const double theta[2] = {p.lambda / p.Cth, 1.0 / (p.R * p.Cth)};
  EstimatorConfig c;
  c.scale << 1e3, 1.0, 2e3, 0.1, 0.06, 1.0;
  constexpr double kPeriod = 1e-3, kNoise = 0.01;
  constexpr std::int64_t kSpacing = 7919;
  int covered[2] = {0, 0}, points = 0;
  double err2[2] = {0, 0}, sigma_sum[2] = {0, 0};
  for (std::uint64_t seed = 1; seed <= 3; ++seed) {
    Estimator est(c);
    test::Plant plant;
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> noise(0.0, kNoise);
    est.update(Measurement{.t = 0.0, .x = 0.0, .xdot = 0.0, .tbar = noise(rng), .voltage = 0.0});
    for (std::int64_t k = 1; k <= 300000; ++k) {
      const double v = test::paper_voltage((k - 1) * kPeriod);
      plant.advance(kPeriod, v, 20);
      const Measurement m{.t = k * kPeriod,
                          .x = plant.x,
                          .xdot = plant.xdot,
                          .tbar = plant.tbar + noise(rng),
                          .voltage = v};
      ASSERT_EQ(est.update(m), UpdateOutcome::applied) << m.t;
      if (k < 100000 || (k - 100000) % kSpacing != 0) continue;
      const Estimate& e = est.estimate();
      ++points;
      for (int i = 0; i < 2; ++i) {
        const double err = e.theta_hat(4 + i) - theta[i], s = e.sigma(4 + i);
        ASSERT_TRUE(std::isfinite(s) && s > 0.0) << m.t;
        covered[i] += std::abs(err) <= 2.0 * s;
        err2[i] += err * err;
        sigma_sum[i] += s;
      }
    }
  }
  ASSERT_EQ(points, 78);
  for (int i = 0; i < 2; ++i) {
    // Binomial(78, 0.954): P(fewer than 69) < 0.5 %.
    EXPECT_GE(covered[i], 69) << "theta" << 5 + i << ": " << covered[i] << "/" << points;
    const double ratio = std::sqrt(err2[i] / points) / (sigma_sum[i] / points);
    EXPECT_GT(ratio, 0.6) << "theta" << 5 + i;
    EXPECT_LT(ratio, 1.6) << "theta" << 5 + i;
    std::printf("theta%d: 2-sigma coverage %d/%d, RMS error / mean sigma %.3g\n", 5 + i, covered[i],
                points, ratio);
  }
}

}  // namespace
}  // namespace scp::estimator

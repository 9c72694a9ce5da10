// The filtered differentiator against closed-form results: a ramp's slope, the analytic
// amplitude and phase of s·ωc²/(s² + 2ζωc s + ωc²), and the H2-norm noise gain.

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>
#include <stdexcept>

#include "daemon/core/velocity/velocity_estimator.hpp"

namespace scp::daemon::velocity {
namespace {

constexpr double kPi = std::numbers::pi;

TEST(VelocityEstimator, FirstSampleStartsAtRest) {
  VelocityEstimator v;
  EXPECT_EQ(v.update(1e-3, 0.0), 0.0);
  // A constant position then gives zero velocity.
  for (int k = 0; k < 100; ++k) EXPECT_NEAR(v.update(1e-3, 1e-3), 0.0, 1e-15);
}

TEST(VelocityEstimator, RampGivesItsSlopeAfterTheTransient) {
  VelocityEstimator v({20.0, 0.707});
  const double slope = 2.5e-4;  // m/s
  const double h = 1e-3;
  double out = v.update(0.0, 0.0);
  for (int k = 1; k <= 1000; ++k) out = v.update(slope * k * h, h);
  // Transient decays as e^{-ζωc t}: e^{-0.707·125.7·1} ≈ 1e-39.
  EXPECT_NEAR(out, slope, 1e-12 * slope + 1e-18);
}

TEST(VelocityEstimator, SinusoidBelowBandwidthHasAnalyticAmplitudeAndPhase) {
  const double fc = 20.0, zeta = 0.707, f = 1.0, h = 1e-3, amp = 1e-3;
  VelocityEstimator v({fc, zeta});
  const double w = 2 * kPi * f, wc = 2 * kPi * fc;
  // Independent closed form: x = A sin(ωt) → ẋ̂ = A ω |H/s| cos(ωt + ∠(H/s)),
  // |H(jω)/(jω)| = ωc² / sqrt((ωc² − ω²)² + (2ζωcω)²), ∠ = −atan2(2ζωcω, ωc² − ω²).
  const double gain = wc * wc / std::hypot(wc * wc - w * w, 2 * zeta * wc * w);
  const double phase = -std::atan2(2 * zeta * wc * w, wc * wc - w * w);
  v.update(0.0, 0.0);
  double max_err = 0.0;
  for (int k = 1; k <= 4000; ++k) {
    const double t = k * h;
    const double out = v.update(amp * std::sin(w * t), h);
    if (t > 2.0) {
      const double expect = amp * w * gain * std::cos(w * t + phase);
      max_err = std::max(max_err, std::abs(out - expect));
    }
  }
  EXPECT_LT(max_err, 1e-4 * amp * w);
  // Low-frequency group delay 2ζ/ωc: the phase lag is ω·2ζ/ωc to first order in ω/ωc (the
  // next term is 0.1 % here, at ω/ωc = 0.05).
  EXPECT_NEAR(-phase / w, v.group_delay_s(), 2e-3 * v.group_delay_s());
}

TEST(VelocityEstimator, WhiteNoiseGainMatchesH2Norm) {
  const double h = 1e-3;
  VelocityEstimator v({20.0, 0.707});
  std::mt19937_64 rng(7);
  std::normal_distribution<double> n(0.0, 1.0);
  v.update(n(rng), 0.0);
  double sum2 = 0.0;
  int count = 0;
  for (int k = 1; k <= 200000; ++k) {
    const double out = v.update(n(rng), h);
    if (k > 1000) {
      sum2 += out * out;
      ++count;
    }
  }
  const double measured = std::sqrt(sum2 / count);
  // sqrt(h ωc³ / (4ζ)) = 26.5 at 20 Hz, 1 kHz; the first-order hold smooths the highest
  // frequencies a little, so allow 15 %.
  const double theory = std::sqrt(h * std::pow(2 * kPi * 20.0, 3) / (4 * 0.707));
  EXPECT_NEAR(v.noise_gain(h), theory, 1e-12 * theory);
  EXPECT_NEAR(measured, theory, 0.15 * theory);
}

TEST(VelocityEstimator, NonFiniteInputIsSkippedAndTheGapBridged) {
  VelocityEstimator v({20.0, 0.707});
  const double slope = 1e-4, h = 1e-3;
  v.update(0.0, 0.0);
  double out = 0.0;
  for (int k = 1; k <= 500; ++k) {
    const double x = (k % 50 == 0) ? std::nan("") : slope * k * h;
    out = v.update(x, h);
    if (k % 50 == 0) {
      EXPECT_TRUE(std::isnan(out));
    }
  }
  for (int k = 501; k <= 1000; ++k) out = v.update(slope * k * h, h);
  EXPECT_NEAR(out, slope, 1e-9 * slope);
  EXPECT_TRUE(std::isnan(v.update(0.0, -1.0)));
  EXPECT_TRUE(std::isnan(v.update(0.0, std::nan(""))));
}

TEST(VelocityEstimator, VaryingPeriodStillExactForARamp) {
  VelocityEstimator v({10.0, 1.0});
  const double slope = -3e-4;
  double t = 0.0;
  v.update(0.0, 0.0);
  double out = 0.0;
  for (int k = 0; k < 3000; ++k) {
    const double dt = (k % 3 == 0) ? 2e-3 : 0.5e-3;
    t += dt;
    out = v.update(slope * t, dt);
  }
  EXPECT_NEAR(out, slope, 1e-9 * std::abs(slope));
}

TEST(VelocityEstimator, ResetStartsAgainAtRest) {
  VelocityEstimator v;
  v.update(0.0, 0.0);
  for (int k = 1; k < 100; ++k) v.update(1e-4 * k, 1e-3);
  v.reset();
  EXPECT_EQ(v.update(5.0, 1e-3), 0.0);
  EXPECT_NEAR(v.update(5.0, 1e-3), 0.0, 1e-12);
}

TEST(VelocityEstimator, RejectsBadSettings) {
  EXPECT_THROW(VelocityEstimator({0.0, 0.7}), std::invalid_argument);
  EXPECT_THROW(VelocityEstimator({20.0, -1.0}), std::invalid_argument);
  EXPECT_THROW(VelocityEstimator({std::nan(""), 0.7}), std::invalid_argument);
}

}  // namespace
}  // namespace scp::daemon::velocity

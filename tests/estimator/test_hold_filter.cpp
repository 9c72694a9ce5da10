#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "estimator/hold_filter.hpp"

namespace scp::estimator {
namespace {

constexpr double kBeta = 3.0;

TEST(HoldFilter, FohIsExactForRamp) {
  // ẏ = −βy + β(a + c t), y(0) = y0 ⇒ y = a + c t − c/β + (y0 − a + c/β) e^{−βt}.
  const double a = 0.7, c = -2.3, y0 = 0.4, h = 1e-3;
  const HoldCoefficients k = HoldCoefficients::make(kBeta, h);
  double y = y0;
  double max_err = 0.0;
  for (int i = 1; i <= 3000; ++i) {
    const double t0 = (i - 1) * h, t1 = i * h;
    y = k.foh(y, a + c * t0, a + c * t1);
    const double exact = a + c * t1 - c / kBeta + (y0 - a + c / kBeta) * std::exp(-kBeta * t1);
    max_err = std::max(max_err, std::abs(y - exact));
  }
  EXPECT_LT(max_err, 1e-12);
}

// Max error over [0, 5] s of the FOH filter driven by sin(ωt), y(0) = 0, against
// y = β/(β²+ω²)·(β sin ωt − ω cos ωt + ω e^{−βt}).
double sine_error(double h) {
  const double w = 2.0;
  const HoldCoefficients k = HoldCoefficients::make(kBeta, h);
  double y = 0.0, max_err = 0.0;
  const int n = static_cast<int>(std::lround(5.0 / h));
  for (int i = 1; i <= n; ++i) {
    const double t0 = (i - 1) * h, t1 = i * h;
    y = k.foh(y, std::sin(w * t0), std::sin(w * t1));
    const double exact =
        kBeta / (kBeta * kBeta + w * w) *
        (kBeta * std::sin(w * t1) - w * std::cos(w * t1) + w * std::exp(-kBeta * t1));
    max_err = std::max(max_err, std::abs(y - exact));
  }
  return max_err;
}

TEST(HoldFilter, FohSineErrorIsSecondOrder) {
  const double e1 = sine_error(1e-2);
  const double e2 = sine_error(5e-3);
  const double e3 = sine_error(1e-3);
  EXPECT_LT(e3, 1e-6);
  EXPECT_GT(e1 / e2, 3.5);  // halving h divides the error by ~4
  EXPECT_LT(e1 / e2, 4.5);
}

TEST(HoldFilter, QuadraticIsExactForParabola) {
  // u = t², y(0) = 0 ⇒ y = t² − 2t/β + 2/β² − (2/β²) e^{−βt}. Nonuniform steps on purpose.
  double y = 0.0, t_prev2 = 0.0, t_prev = 0.0, max_err = 0.0;
  const auto u = [](double t) { return t * t; };
  double t = 0.0;
  for (int i = 1; i <= 2000; ++i) {
    const double h = (i % 2 == 0) ? 1e-3 : 1.5e-3;
    t += h;
    const HoldCoefficients k = HoldCoefficients::make(kBeta, h);
    y = i == 1 ? k.foh(y, u(t_prev), u(t))
               : k.quadratic(y, u(t_prev2), u(t_prev), u(t), t_prev - t_prev2);
    t_prev2 = t_prev;
    t_prev = t;
    if (i == 1) {  // FOH on the first step is not exact; restart the comparison from here
      const double b2 = kBeta * kBeta;
      y = t * t - 2 * t / kBeta + 2 / b2 - 2 / b2 * std::exp(-kBeta * t);
      continue;
    }
    const double b2 = kBeta * kBeta;
    const double exact = t * t - 2 * t / kBeta + 2 / b2 - 2 / b2 * std::exp(-kBeta * t);
    max_err = std::max(max_err, std::abs(y - exact));
  }
  EXPECT_LT(max_err, 1e-12);
}

TEST(HoldFilter, ZohIsExactForStep) {
  const double h = 1e-3;
  const HoldCoefficients k = HoldCoefficients::make(kBeta, h);
  double y = 0.0, max_err = 0.0;
  for (int i = 1; i <= 2000; ++i) {
    y = k.zoh_step(y, 1.0);
    max_err = std::max(max_err, std::abs(y - (1.0 - std::exp(-kBeta * i * h))));
  }
  EXPECT_LT(max_err, 1e-13);
}

// A DAC whose command lands mid-interval: u_prev over the first h − τ, u_next over the last τ.
// The split step must equal the two ZOH sub-steps composed (and the closed form), for any τ.
TEST(HoldFilter, ZohSplitStepIsTwoExactSubSteps) {
  const double h = 0.01, y0 = 0.37, u_prev = 2.1, u_next = 2.6;
  const HoldCoefficients k = HoldCoefficients::make(kBeta, h);
  for (const double tail : {1e-6, 0.002, 0.005, 0.0099}) {
    const HoldCoefficients first = HoldCoefficients::make(kBeta, h - tail);
    const HoldCoefficients last = HoldCoefficients::make(kBeta, tail);
    const double composed = last.zoh_step(first.zoh_step(y0, u_prev), u_next);
    EXPECT_NEAR(k.zoh_split_step(y0, u_prev, u_next, kBeta, tail), composed, 1e-15) << tail;
    const double exact =
        u_next + (u_prev - u_next) * std::exp(-kBeta * tail) + (y0 - u_prev) * std::exp(-kBeta * h);
    EXPECT_NEAR(k.zoh_split_step(y0, u_prev, u_next, kBeta, tail), exact, 1e-14) << tail;
  }
  // τ = h is the plain ZOH step of u_next.
  EXPECT_NEAR(k.zoh_split_step(y0, u_prev, u_next, kBeta, h), k.zoh_step(y0, u_next), 1e-15);
}

TEST(HoldFilter, CoefficientsSumToOneMinusPhi) {
  for (double h : {1e-6, 1e-3, 0.1, 2.0}) {
    const HoldCoefficients k = HoldCoefficients::make(kBeta, h);
    EXPECT_NEAR(k.phi, std::exp(-kBeta * h), 1e-15);
    EXPECT_NEAR(k.c0 + k.c1, 1.0 - k.phi, 1e-15);
    EXPECT_GE(k.c0, 0.0);
    EXPECT_GE(k.c1, 0.0);
  }
}

}  // namespace
}  // namespace scp::estimator

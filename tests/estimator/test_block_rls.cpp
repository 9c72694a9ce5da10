#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "estimator/block_rls.hpp"

namespace scp::estimator {
namespace {

// Hand arithmetic for a 2-parameter block: explicit 2×2 inverses, no Eigen solves.
struct Hand {
  double r11, r12, r22;  // information, scaled coordinates
  double v1, v2;         // ϑ
  double eps_num = 0.0, eps_den = 0.0;
};

void hand_step(Hand& s, double ws1, double ws2, double eps, double h, double lam, double rmin) {
  const double a11 = s.r11 + ws1 * ws1, a12 = s.r12 + ws1 * ws2, a22 = s.r22 + ws2 * ws2;
  const double det = a11 * a22 - a12 * a12;
  const double b1 = ws1 * eps, b2 = ws2 * eps;
  s.v1 += h * (a22 * b1 - a12 * b2) / det;
  s.v2 += h * (-a12 * b1 + a11 * b2) / det;
  const double d = std::exp(-lam * h), g = (1.0 - d) / lam;
  s.r11 = d * (s.r11 - rmin) + rmin + g * ws1 * ws1;
  s.r12 = d * s.r12 + g * ws1 * ws2;
  s.r22 = d * (s.r22 - rmin) + rmin + g * ws2 * ws2;
  s.eps_num = d * s.eps_num + g * eps * eps;
  s.eps_den = d * s.eps_den + g;
}

TEST(BlockRls, TwoStepsMatchHandComputation) {
  BlockRls<2>::Settings set;
  set.forgetting = 0.5;
  set.p0 = 10.0;
  set.p_max = 1e3;
  set.beta = 2.0;
  set.scale << 2.0, 0.5;
  set.theta0 << 1.0, -1.0;
  BlockRls<2> rls(set);

  const double rmin = 1e-3;
  Hand hand{.r11 = 0.1, .r12 = 0.0, .r22 = 0.1, .v1 = 0.5, .v2 = -2.0};
  // Step 1: w = [0.3, −0.7] → w_s = [0.6, −0.35]; step 2: w = [−0.1, 0.4] → w_s = [−0.2, 0.2].
  rls.step(Eigen::RowVector2d(0.3, -0.7), 0.2, ForgettingStep::make(0.5, 0.01));
  hand_step(hand, 0.6, -0.35, 0.2, 0.01, 0.5, rmin);
  EXPECT_NEAR(rls.theta()(0), 2.0 * hand.v1, 1e-14);
  EXPECT_NEAR(rls.theta()(1), 0.5 * hand.v2, 1e-14);

  rls.step(Eigen::RowVector2d(-0.1, 0.4), -0.05, ForgettingStep::make(0.5, 0.02));
  hand_step(hand, -0.2, 0.2, -0.05, 0.02, 0.5, rmin);
  EXPECT_NEAR(rls.theta()(0), 2.0 * hand.v1, 1e-14);
  EXPECT_NEAR(rls.theta()(1), 0.5 * hand.v2, 1e-14);
  const auto& r = rls.info_scaled();
  EXPECT_NEAR(r(0, 0), hand.r11, 1e-15);
  EXPECT_NEAR(r(0, 1), hand.r12, 1e-15);
  EXPECT_NEAR(r(1, 0), hand.r12, 1e-15);
  EXPECT_NEAR(r(1, 1), hand.r22, 1e-15);

  // σ_i = sqrt(mean ε² · P_ii / β) · D_i with P = R⁻¹.
  const double mean = hand.eps_num / hand.eps_den;
  EXPECT_NEAR(rls.eps2_mean(), mean, 1e-15);
  const double det = hand.r11 * hand.r22 - hand.r12 * hand.r12;
  EXPECT_NEAR(rls.sigma()(0), 2.0 * std::sqrt(mean * (hand.r22 / det) / 2.0), 1e-12);
  EXPECT_NEAR(rls.sigma()(1), 0.5 * std::sqrt(mean * (hand.r11 / det) / 2.0), 1e-12);
  // Largest eigenvalue of P = 1/smallest eigenvalue of R (2×2 closed form).
  const double tr = hand.r11 + hand.r22;
  const double l_min = 0.5 * (tr - std::sqrt(tr * tr - 4.0 * det));
  EXPECT_NEAR(rls.p_max_eig(), 1.0 / l_min, 1e-9 / l_min);
  const double window = (1.0 - std::exp(-0.5 * 0.03)) / 0.5;
  EXPECT_NEAR(rls.window(), window, 1e-15);
  // Scale-free excitation: λ_min of the data's information in correlation form, where what R
  // holds without data is the floor plus the prior's remainder e^{−λP t}(1/p0 − R_min).
  const double r0 = rmin + (1.0 - 0.5 * window) * (0.1 - rmin);
  const double c11 = (hand.r11 - r0) / hand.r11, c22 = (hand.r22 - r0) / hand.r22;
  const double c12 = hand.r12 / std::sqrt(hand.r11 * hand.r22);
  const double c_min = 0.5 * (c11 + c22 - std::sqrt((c11 - c22) * (c11 - c22) + 4.0 * c12 * c12));
  EXPECT_NEAR(rls.excitation(), c_min, 1e-12);
  EXPECT_GT(rls.excitation(), 0.0);
}

// The regressor of the mechanical block, four independent tones (a persistently exciting
// signal), with column `scaled` multiplied by `factor` (a change of units: x in mm, not m).
Eigen::RowVector4d tones(double t, int scaled, double factor) {
  constexpr double kTwoPi = 6.283185307179586;
  Eigen::RowVector4d w(std::sin(kTwoPi * 0.7 * t), 0.5 * std::cos(kTwoPi * 1.3 * t),
                       0.2 * std::sin(kTwoPi * 2.9 * t + 1.0),
                       1.0 + 0.3 * std::sin(kTwoPi * 0.2 * t));
  w(scaled) *= factor;
  return w;
}

// Issue 9: "converged" and the excitation figure must mean the same on any actuator and in any
// units. The measure is that of the data's information in correlation form, so scaling a column
// by 1e3 leaves it unchanged (to rounding and the floor's share) while the raw λ_min(R) moves by
// orders of magnitude; and it falls once the regressor stops exciting every direction (held at a
// constant, as the plant's regressor is when the voltage is held).
TEST(BlockRls, ExcitationIsScaleFreeAndFallsWhenTheExcitationStops) {
  BlockRls<4>::Settings set;  // λP 0.8 1/s, p0 100, p_max 1e12
  BlockRls<4> metres(set), millimetres(set);
  const auto f = ForgettingStep::make(set.forgetting, 1e-3);
  double t = 0.0;
  for (int k = 0; k < 30000; ++k, t += 1e-3) {  // 30 s: the prior has faded to e^{-24}
    metres.step(tones(t, 2, 1.0), 0.0, f);
    millimetres.step(tones(t, 2, 1e3), 0.0, f);
  }
  const double excited = metres.excitation();
  std::printf("[ figures ] excitation %.6g (column scaled 1e3: %.6g); p_max_eig %.3g vs %.3g\n",
              excited, millimetres.excitation(), metres.p_max_eig(), millimetres.p_max_eig());
  EXPECT_GT(excited, 0.01);
  EXPECT_LE(excited, 1.0);
  EXPECT_NEAR(millimetres.excitation(), excited, 1e-9 * excited);
  // What the old, raw measure saw: the weakest direction's information changed by the units.
  EXPECT_GT(std::abs(std::log10(millimetres.p_max_eig() / metres.p_max_eig())), std::log10(5.0));

  // Excitation stops: the regressor is held where it was (the plant at a held voltage).
  const Eigen::RowVector4d held = tones(t, 2, 1.0);
  for (int k = 0; k < 10000; ++k) metres.step(held, 0.0, f);  // 10 s = 8 forgetting times
  std::printf("[ figures ] excitation after 10 s of a held regressor: %.3g\n", metres.excitation());
  EXPECT_LT(metres.excitation(), 1e-2 * excited);
}

TEST(BlockRls, ZeroRegressorLeavesEstimateAndDecaysTowardFloor) {
  BlockRls<2>::Settings set;
  set.p0 = 1.0;
  set.p_max = 100.0;
  set.theta0 << 3.0, 4.0;
  BlockRls<2> rls(set);
  for (int i = 0; i < 100000; ++i) {
    rls.step(Eigen::RowVector2d::Zero(), 5.0, ForgettingStep::make(0.8, 1e-3));
  }
  EXPECT_EQ(rls.theta()(0), 3.0);
  EXPECT_EQ(rls.theta()(1), 4.0);
  // R = e^{−80}(1 − 0.01) + 0.01 → P ≈ p_max, never above.
  EXPECT_LE(rls.p_max_eig(), 100.0);
  EXPECT_GT(rls.p_max_eig(), 99.99);
}

}  // namespace
}  // namespace scp::estimator

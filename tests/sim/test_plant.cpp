// The plant against closed-form solutions of eqs. (1)-(2), not against its own output.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "drivers/sim/plant.hpp"

namespace scp::drivers::sim {
namespace {

// Table I, written out again so that a wrong default in PlantParams is caught.
constexpr double kM = 0.1, kR = 1.0, kCth = 0.9090, kLambda = 0.0540, kB = 124.7, kK = 181.3,
                 kAlpha1 = 0.08, kAlpha2 = 0.01;

TEST(Plant, DefaultsAreTableOne) {
  const PlantParams p;
  EXPECT_EQ(p.m, kM);
  EXPECT_EQ(p.R, kR);
  EXPECT_EQ(p.Cth, kCth);
  EXPECT_EQ(p.lambda, kLambda);
  EXPECT_EQ(p.b, kB);
  EXPECT_EQ(p.k, kK);
  EXPECT_EQ(p.alpha1, kAlpha1);
  EXPECT_EQ(p.alpha2, kAlpha2);
  const auto th = theta_of(p);
  const double expected[6] = {1247, 0.8, 1813, 0.1, 0.0594059405940594, 1.1001100110011};
  for (int i = 0; i < 6; ++i) EXPECT_NEAR(th[i], expected[i], 1e-12 * expected[i]) << i;
}

TEST(Plant, ThermalStepMatchesClosedForm) {
  Plant plant;
  const double v = 2.0, dt = 1e-3;
  const double tss = v * v / (kR * kLambda);
  for (int k = 1; k <= 30000; ++k) {
    plant.step(v, dt);
    if (k % 1000 == 0) {
      const double t = k * dt;
      const double expected = tss * (1.0 - std::exp(-kLambda * t / kCth));
      ASSERT_NEAR(plant.tbar(), expected, 1e-10 * tss) << "t=" << t;
    }
  }
}

TEST(Plant, SteadyStateDisplacement) {
  Plant plant;
  const double v = 1.0;
  // 400 s ≈ 26 thermal time constants: the transient is below 1e-11 of the final value.
  for (int k = 0; k < 4000; ++k) plant.step(v, 0.1);
  const double tss = v * v / (kR * kLambda);
  const double x_ss = -kAlpha2 * tss / kK;
  EXPECT_NEAR(plant.tbar(), tss, 1e-9 * tss);
  EXPECT_NEAR(plant.x(), x_ss, 1e-9 * std::abs(x_ss));
  EXPECT_NEAR(plant.xdot(), 0.0, 1e-12);
}

// With a huge thermal mass and no voltage, T̄ stays at its initial value (relative change
// λt/Cth ≈ 5e-13 over 10 s), so eq. (1) becomes m ẍ + c ẋ + k x = −α2 T̄ with c = b + α1 T̄:
// x(t) = x_ss + A e^{r1 t} + B e^{r2 t}, r1,2 the (real) roots of m r² + c r + k.
TEST(Plant, MechanicalStepMatchesClosedFormWithHeldTemperature) {
  PlantParams p;
  p.Cth = 1e12;
  Plant plant(p);
  const double tbar = 20.0;
  plant.set_state(0.0, 0.0, tbar);
  const double c = kB + kAlpha1 * tbar;
  const double disc = std::sqrt(c * c - 4.0 * kM * kK);
  const double r1 = (-c + disc) / (2.0 * kM), r2 = (-c - disc) / (2.0 * kM);
  ASSERT_NEAR(r1, -1.4549, 0.02);  // the slow pole the notes quote (at T̄ = 0: −1.455)
  const double x_ss = -kAlpha2 * tbar / kK;
  // x(0) = 0, ẋ(0) = 0  →  A + B = −x_ss,  r1 A + r2 B = 0.
  const double a = -x_ss * r2 / (r2 - r1), b = x_ss * r1 / (r2 - r1);
  double max_err = 0.0, max_err_v = 0.0;
  for (int k = 1; k <= 10000; ++k) {
    plant.step(0.0, 1e-3);
    const double t = k * 1e-3;
    const double x = x_ss + a * std::exp(r1 * t) + b * std::exp(r2 * t);
    const double xd = r1 * a * std::exp(r1 * t) + r2 * b * std::exp(r2 * t);
    max_err = std::max(max_err, std::abs(plant.x() - x));
    max_err_v = std::max(max_err_v, std::abs(plant.xdot() - xd));
  }
  EXPECT_LT(max_err, 1e-9 * std::abs(x_ss));
  // |ẋ| peaks near |x_ss|·|r1|; RK4's error on the fast transient (h·r2 ≈ −0.06) is ~5e-8 of it.
  EXPECT_LT(max_err_v, 2e-7 * std::abs(x_ss * r1));
  EXPECT_NEAR(plant.tbar(), tbar, 1e-9);
}

double paper_voltage(double t) {
  const double w1 = 2.0 * std::numbers::pi * 0.006, w2 = 2.0 * std::numbers::pi * 0.1;
  const double h = std::numbers::pi / 2.0;
  return 1.6 +
         0.4 * (std::sin(w1 * t - h) + std::sin(w1 * t) + std::sin(w2 * t) + std::sin(w2 * t - h));
}

TEST(Plant, DefaultSubstepsAccurateAtOneMillisecond) {
  Plant coarse(PlantParams{}, 20), fine(PlantParams{}, 400), one(PlantParams{}, 1);
  double max_x = 0.0, err = 0.0, err_one = 0.0, err_v = 0.0;
  for (int k = 0; k < 20000; ++k) {
    const double v = paper_voltage(k * 1e-3);
    coarse.step(v, 1e-3);
    fine.step(v, 1e-3);
    one.step(v, 1e-3);
    max_x = std::max(max_x, std::abs(fine.x()));
    err = std::max(err, std::abs(coarse.x() - fine.x()));
    err_v = std::max(err_v, std::abs(coarse.xdot() - fine.xdot()));
    err_one = std::max(err_one, std::abs(one.x() - fine.x()));
  }
  ASSERT_GT(max_x, 1e-4);
  EXPECT_LT(err, 1e-9 * max_x);
  EXPECT_LT(err_v, 1e-8 * max_x);
  // Even a single RK4 step per ms (h·1245.5 ≈ 1.25) is stable, though less accurate.
  EXPECT_LT(err_one, 1e-3 * max_x);
}

TEST(Plant, StableOverThousandSeconds) {
  Plant plant;
  // Bounds from the closed forms: T̄ ≤ V²max/(Rλ) = 3.2²/0.054, |x| ≤ α2·T̄max/k.
  const double tbar_max = 3.2 * 3.2 / (kR * kLambda);
  const double x_max = kAlpha2 * tbar_max / kK;
  for (int k = 0; k < 1000000; ++k) {
    plant.step(paper_voltage(k * 1e-3), 1e-3);
    if (k % 1000 == 0) {
      ASSERT_TRUE(std::isfinite(plant.x()) && std::isfinite(plant.xdot())) << k;
      ASSERT_LE(std::abs(plant.x()), x_max);
      ASSERT_GE(plant.tbar(), 0.0);
      ASSERT_LE(plant.tbar(), tbar_max);
    }
  }
  EXPECT_NEAR(plant.time(), 1000.0, 1e-6);
}

TEST(Plant, LongStepsGetMoreSubsteps) {
  // One 5 s step must equal 5000 steps of 1 ms (the sub-step count scales with dt).
  Plant a, b;
  a.step(2.5, 5.0);
  for (int k = 0; k < 5000; ++k) b.step(2.5, 1e-3);
  EXPECT_NEAR(a.x(), b.x(), 1e-12);
  EXPECT_NEAR(a.tbar(), b.tbar(), 1e-10);
}

TEST(Plant, IgnoresInvalidSteps) {
  Plant plant;
  plant.step(std::nan(""), 1e-3);
  plant.step(1.0, -1e-3);
  plant.step(1.0, std::numeric_limits<double>::infinity());
  EXPECT_EQ(plant.time(), 0.0);
  EXPECT_EQ(plant.tbar(), 0.0);
}

TEST(Plant, DriftAppliesToParameters) {
  PlantDrift drift;
  drift.k = 100.0;  // +100 × per hour: +50 % at 18 s
  Plant plant(PlantParams{}, 20, drift);
  plant.step(0.0, 36.0);
  // Parameters of the last step are taken at its midpoint, t = 18 s.
  EXPECT_NEAR(plant.params().k, kK * 1.5, 1e-12);
  EXPECT_EQ(plant.params().m, kM);
  const PlantParams d = drifted(PlantParams{}, drift, 3600.0);
  EXPECT_NEAR(d.k, kK * 101.0, 1e-9);
  // A large negative rate cannot make a parameter non-positive.
  PlantDrift shrink;
  shrink.m = -10.0;
  EXPECT_GT(drifted(PlantParams{}, shrink, 3600.0).m, 0.0);
}

}  // namespace
}  // namespace scp::drivers::sim

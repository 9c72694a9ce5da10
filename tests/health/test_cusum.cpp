// The CUSUM: Siegmund's ARL against the published tables, the design against its own formula,
// and, by simulation, the run length under no change and the delay after one.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "health/cusum.hpp"

namespace scp::health {
namespace {

// Blocks until the CUSUM alarms, for increments N(mean, 1).
double run_length(TwoSidedCusum& c, double mean, std::mt19937_64& rng) {
  std::normal_distribution<double> n;
  c.reset();
  for (int i = 1;; ++i)
    if (c.update(mean + n(rng), i)) return i;
}

TEST(Cusum, SiegmundMatchesPublishedRunLengths) {
  // Two-sided, k = 0.5 (Montgomery's table: h = 4 → 168, h = 5 → 465; ARL(1σ) 8.38, 10.4).
  EXPECT_NEAR(1.0 / cusum_false_alarm_rate(0.5, 4.0, 0.0), 168.0, 168.0 * 0.01);
  EXPECT_NEAR(1.0 / cusum_false_alarm_rate(0.5, 5.0, 0.0), 465.0, 465.0 * 0.015);
  EXPECT_NEAR(siegmund_arl(1.0, 0.5, 4.0), 8.38, 0.1);
  EXPECT_NEAR(siegmund_arl(1.0, 0.5, 5.0), 10.4, 0.1);
}

TEST(Cusum, DesignMeetsItsFalseAlarmRate) {
  for (double shift : {0.5, 1.0, 2.0, 10.0})
    for (double arl0 : {1e3, 1e6}) {
      const CusumDesign d = design_cusum(shift, arl0, 0.0);
      EXPECT_LE(d.k, 1.0);
      EXPECT_NEAR(cusum_false_alarm_rate(d.k, d.h, 0.0) * arl0, 1.0, 1e-6) << shift << " " << arl0;
    }
  // An uncertain reference biases every block alike: the design asks for a higher threshold.
  const CusumDesign exact = design_cusum(1.0, 1e6, 0.0);
  const CusumDesign biased = design_cusum(1.0, 1e6, 0.01);
  EXPECT_GT(biased.h, exact.h);
  EXPECT_NEAR(cusum_false_alarm_rate(biased.k, biased.h, 0.01) * 1e6, 1.0, 1e-6);
}

TEST(Cusum, SimulatedRunLengthsMatchTheDesign) {
  // ARL₀ = 300 blocks: 400 runs estimate it within ~5 % (σ of a geometric-like run length is
  // about its mean); Siegmund's approximation itself is within a few %.
  const CusumDesign d = design_cusum(1.0, 300.0, 0.0);
  TwoSidedCusum c(d);
  std::mt19937_64 rng(7);
  double total = 0.0;
  const int runs = 400;
  for (int r = 0; r < runs; ++r) total += run_length(c, 0.0, rng);
  EXPECT_NEAR(total / runs / 300.0, 1.0, 0.15);
  // After a shift of the design size, from a zero start.
  double delay = 0.0;
  for (int r = 0; r < runs; ++r) delay += run_length(c, 1.0, rng);
  EXPECT_NEAR(delay / runs / cusum_delay(d, 1.0), 1.0, 0.1);
}

TEST(Cusum, OnsetIsWhereTheStatisticLeftZero) {
  TwoSidedCusum c(design_cusum(2.0, 1e6, 0.0));
  std::mt19937_64 rng(3);
  std::normal_distribution<double> n;
  double t = 0.0;
  for (; t < 200.0; t += 1.0) ASSERT_FALSE(c.update(n(rng), t));
  bool alarm = false;
  for (; t < 260.0 && !alarm; t += 1.0) alarm = c.update(-2.0 + n(rng), t);
  ASSERT_TRUE(alarm);
  EXPECT_EQ(c.direction(), -1);
  EXPECT_NEAR(c.onset(), 200.0, 3.0);
  EXPECT_LT(t - 200.0, 15.0);
}

}  // namespace
}  // namespace scp::health

// Naming a mechanical drift by the trends of θ's ratios to k/m (drift_naming.hpp), on synthetic
// windows that also scatter beyond their covariance as a drifting plant's constant-θ windows do
// (15 % along θ1..θ4's common scale, 10 % in α1/m alone): the drifting parameter named with its
// rate, nothing named for a plant that does not drift or whose mass drifts.
#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "health/drift_naming.hpp"
#include "tests/health/synthetic_windows.hpp"

namespace scp::health {
namespace {

constexpr double kWindowS = 120.0;
constexpr double kZ = 3.29;

// θ with the physical parameter `index` of [b, α1, k, α2] drifting at `per_hour` (relative), m
// when index is 4; θ1..θ4 are those over m.
test::ThetaOfTime drifting(int index, double per_hour) {
  return [=](double t) {
    Vector6 th = test::paper_theta();
    const double factor = 1.0 + per_hour * t / 3600.0;
    if (index < 4) th[index] *= factor;
    if (index == 4) th.head<4>() /= factor;
    return th;
  };
}

std::vector<WindowEstimate> misfit_windows(const test::ThetaOfTime& theta, double until,
                                           std::uint64_t seed) {
  const Matrix6 c = test::window_covariance_300s(0.008 * std::sqrt(300.0 / kWindowS));
  test::WindowStream stream(theta, c, kWindowS, 30.0, seed);
  std::mt19937_64 rng(seed + 77);
  std::normal_distribution<double> normal;
  std::vector<WindowEstimate> windows;
  for (WindowEstimate w = stream.next(); w.t_end <= until; w = stream.next()) {
    w.theta.head<4>() *= 1.0 + 0.15 * normal(rng);
    w.theta[1] *= 1.0 + 0.10 * normal(rng);  // α1/m absorbs part of the misfit
    windows.push_back(w);
  }
  return windows;
}

TEST(DriftNaming, NamesTheDriftingParameterWithItsRate) {
  const struct {
    int physical;  // b, α1, k, α2
    int theta;     // the θ index named
    double theta_per_hour;
  } cases[] = {{0, 0, 0.2}, {2, 2, 0.2}, {3, 3, -0.2}};
  for (const auto& c : cases) {
    for (std::uint64_t seed : {1u, 2u, 3u}) {
      const auto windows = misfit_windows(drifting(c.physical, c.theta_per_hour), 900.0, seed);
      const DriftName name = name_mechanical_drift(windows, kZ);
      ASSERT_EQ(name.parameter, c.theta) << c.physical << " seed " << seed;
      EXPECT_TRUE(name.trend.drifting);
      EXPECT_NEAR(
          name.trend.relative_per_hour, c.theta_per_hour,
          std::max(0.03, 4.0 * name.trend.sigma_per_hour / std::abs(windows.back().theta[c.theta])))
          << c.physical << " seed " << seed;
    }
  }
}

TEST(DriftNaming, NamesNothingWhenTheRatiosHold) {
  for (std::uint64_t seed : {1u, 2u, 3u, 4u, 5u}) {
    EXPECT_EQ(name_mechanical_drift(misfit_windows(drifting(0, 0.0), 900.0, seed), kZ).parameter,
              -1)
        << "steady, seed " << seed;
    EXPECT_EQ(name_mechanical_drift(misfit_windows(drifting(4, 0.2), 900.0, seed), kZ).parameter,
              -1)
        << "mass, seed " << seed;
  }
}

TEST(DriftNaming, NeedsThreeWindowsThatShareNoData) {
  // Windows up to 300 s: two disjoint ones at most.
  EXPECT_EQ(name_mechanical_drift(misfit_windows(drifting(0, 0.2), 300.0, 1), kZ).parameter, -1);
}

}  // namespace
}  // namespace scp::health

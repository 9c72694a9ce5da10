// The landing filter's covariance (refine/landing_filter.hpp) against the model itself: the error
// a landing δ off puts into [x, ẋ, T̄], measured by simulating the interval twice with the
// switch moved by δ, must be the direction the filter's P holds, at the sample and one interval
// later. And the filtered pass's gradient against central differences of its own cost, every
// slot the fit can free included.
#include <gtest/gtest.h>

#include <cmath>

#include "refine/landing_filter.hpp"
#include "refine/model_simulator.hpp"
#include "refine/residual_pass.hpp"
#include "tests/refine/record.hpp"

namespace scp::refine {
namespace {

// ∂[x, ẋ, T̄]/∂δ at `cur` for a switch δ later than recorded, by central differences.
Eigen::Vector3d landing_sensitivity(const Vector6& theta, const ModelState& start,
                                    const WindowSample& prev, const WindowSample& cur,
                                    const WindowSample* next, double delta) {
  auto run = [&](double shift) {
    ModelState s = start;
    ThermalCache cache;
    advance_interval(theta, prev, cur, shift, s, cache);
    if (next != nullptr) advance_interval(theta, cur, *next, 0.0, s, cache);
    return Eigen::Vector3d(s.x, s.xdot, s.tbar);
  };
  return (run(delta) - run(-delta)) / (2.0 * delta);
}

void expect_same_direction(const Eigen::Matrix3d& p, const Eigen::Vector3d& d) {
  // P = s·v vᵀ with s = 1: v must be ±d, component by component: v to 1 %, so P to 2 %. The
  // filter linearizes at the interval's mean state, not along the trajectory: measured 0.2 % on
  // the paper's actuator, 0.75 % on the underdamped one (whose ẋ turns within the interval);
  // linearized at the interval's start, 3 %. A covariance needs no more.
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      const double expected = d[i] * d[j];
      EXPECT_NEAR(p(i, j), expected, 2e-2 * std::abs(expected) + 1e-30)
          << "P(" << i << ", " << j << ")";
    }
  }
}

TEST(LandingFilter, HoldsTheErrorALandingPutsIntoEveryState) {
  for (const auto& params : {test::paper_actuator(), test::underdamped_actuator()}) {
    const Vector6 theta = test::theta_of(params);
    // Mid-experiment: warm, moving, the voltage stepping up 6.4 ms into a 10 ms interval.
    const ModelState start{-2e-4, 3e-5, 6.0};
    const WindowSample prev{100.0, 0.0, 0.0, 1.0, 99.0};
    const WindowSample cur{100.010, 0.0, 0.0, 3.0, 100.0064};
    const WindowSample next{100.020, 0.0, 0.0, 3.0, 100.0064};
    const double since = cur.t - cur.voltage_since;
    const double step = theta[5] * (cur.voltage * cur.voltage - prev.voltage * prev.voltage);

    ModelState mid = start;
    ThermalCache cache;
    advance_interval(theta, prev, cur, 0.0, mid, cache);
    ModelState end = mid;
    advance_interval(theta, cur, next, 0.0, end, cache);
    LandingFilter filter;
    filter.predict(theta, start, mid, cur.t - prev.t, since, step, 1.0);
    const Eigen::Vector3d at_sample = landing_sensitivity(theta, start, prev, cur, nullptr, 1e-6);
    // The T̄ error, and ẋ's that already followed it through the fast pole, are not small.
    EXPECT_LT(at_sample[2], 0.0);
    EXPECT_GT(std::abs(at_sample[1]),
              1e-3 * std::abs(at_sample[2]) * std::abs(theta[3]) / (std::abs(theta[0]) + 1.0));
    expect_same_direction(filter.covariance(), at_sample);

    // One interval later, with no landing of its own: propagated by the linearized transition.
    filter.predict(theta, mid, end, next.t - cur.t, 0.0, 0.0, 1.0);
    const Eigen::Vector3d later = landing_sensitivity(theta, start, prev, cur, &next, 1e-6);
    expect_same_direction(filter.covariance(), later);
  }
}

TEST(LandingFilter, ATbarInnovationCorrectsXByTheShareTbarsErrorExplains) {
  const Vector6 theta = test::theta_of(test::paper_actuator());
  LandingFilter filter;
  const ModelState start{-2e-4, 3e-5, 6.0};
  filter.predict(theta, start, start, 0.010, 0.0036, theta[5] * 8.0, 1e-9);
  for (int k = 0; k < 50; ++k) filter.predict(theta, start, start, 0.010, 0.0, 0.0, 1e-9);
  const Eigen::Matrix3d before = filter.covariance();
  const double r = 0.25 * before(2, 2);
  const Eigen::Vector3d gain = filter.update_with_tbar(r, 1.0);
  // The regression of x's and ẋ's errors on T̄'s innovation.
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(gain[i], before(i, 2) / (before(2, 2) + r), 1e-12);
  // T̄'s variance falls to P·R/(P + R); the rest stays symmetric positive semi-definite.
  const Eigen::Matrix3d after = filter.covariance();
  EXPECT_NEAR(after(2, 2), before(2, 2) * r / (before(2, 2) + r), 1e-9 * before(2, 2));
  EXPECT_EQ(after, after.transpose());
  EXPECT_GE(after(0, 0), -1e-30);
  EXPECT_LE(after(0, 0), before(0, 0));
  // A sample given no weight does not update.
  LandingFilter untouched = filter;
  EXPECT_EQ(untouched.update_with_tbar(r, 0.0), Eigen::Vector3d::Zero());
  EXPECT_EQ(untouched.covariance(), after);
}

// The pass's JᵀWr is −½ ∂cost/∂p of the cost it reports, with the filter's gains fixed by the
// reference trajectory (they do not depend on p). The filter corrects the state with T̄'s
// innovation, so a term of T̄'s reading (the ambient's offset and drift, the sensor's lag) reaches
// the state, and x, through it: a gradient that left those terms open-loop was 17-79 % off there.
TEST(LandingFilter, TheFilteredPassesGradientIsItsCostsDerivative) {
  const auto params = test::paper_actuator();
  const auto w = test::jittered_link_record(params, 20.0, 40e-6, 7);
  ParamVector p = param_vector(test::theta_of(params) * 1.05, Eigen::Vector3d(0.0, 0.0, 0.0));
  p[kXZeroSlot] = 2e-7;
  p[kAmbientOffsetSlot] = 0.05;
  p[kAmbientDriftSlot] = 1e-4;
  p[kSensorLagSlot] = 0.02;
  PassSettings ps;
  ps.sensor_lag = true;
  ps.weight = {1.0 / (1e-7 * 1e-7), 1.0 / (1e-3 * 1e-3)};
  ps.timing = true;
  ps.timing_variance = 40e-6 * 40e-6;
  ps.timing_reference = p;
  ps.landing_jitter = true;
  const PassResult at = residual_pass(w, p, ps);
  ASSERT_TRUE(at.finite);
  for (const int slot : {kDamping, kStiffness, kThermalForce, kCooling, kHeating, kTbar0,
                         kXZeroSlot, kAmbientOffsetSlot, kAmbientDriftSlot, kSensorLagSlot}) {
    const double h = 1e-6 * std::max(std::abs(p[slot]), slot == kTbar0 ? 1.0 : 1e-3);
    ParamVector up = p, down = p;
    up[slot] += h;
    down[slot] -= h;
    const double derivative =
        (residual_pass(w, up, ps).cost - residual_pass(w, down, ps).cost) / (2.0 * h);
    EXPECT_NEAR(at.jtwr[slot], -0.5 * derivative, 1e-4 * std::abs(derivative) + 1e-9)
        << "slot " << slot;
  }
}

}  // namespace
}  // namespace scp::refine

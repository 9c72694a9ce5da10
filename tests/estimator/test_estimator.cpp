// Unit behaviour of Estimator: sample validation, restore, config rejection, initialization.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "estimator/estimator.hpp"
#include "tests/estimator/synthetic_trajectory.hpp"

namespace scp::estimator {
namespace {

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

using test::sample_at;

EstimatorConfig scaled_config() {
  EstimatorConfig c;
  c.scale << 1e3, 1.0, 2e3, 0.1, 0.06, 1.0;
  return c;
}

void expect_same_state(const State& a, const State& b) {
  EXPECT_EQ(a.theta_hat, b.theta_hat);
  EXPECT_EQ(a.info_mech, b.info_mech);
  EXPECT_EQ(a.info_thermal, b.info_thermal);
  EXPECT_EQ(a.eps2_mean, b.eps2_mean);
  EXPECT_EQ(a.t, b.t);
}

TEST(Estimator, FirstSampleInitializesWithZeroFilteredSignals) {
  Estimator est(scaled_config());
  EXPECT_EQ(est.update(sample_at(0)), UpdateOutcome::initialized);
  EXPECT_EQ(est.estimate().af, Vector2::Zero());
  EXPECT_EQ(est.filtered_regressor(), Regressor::Zero());
  EXPECT_EQ(est.estimate().updates, 0u);
  EXPECT_EQ(est.update(sample_at(1)), UpdateOutcome::applied);
  EXPECT_EQ(est.estimate().updates, 1u);
}

TEST(Estimator, BadSamplesAreSkippedCountedAndChangeNothing) {
  Estimator est(scaled_config());
  Estimator twin(scaled_config());  // sees only the good samples
  for (int k = 0; k < 500; ++k) {
    est.update(sample_at(k));
    twin.update(sample_at(k));
  }
  const State before = est.state();

  Measurement m = sample_at(500);
  Measurement bad = m;
  bad.x = kNan;
  EXPECT_EQ(est.update(bad), UpdateOutcome::skipped_nonfinite);
  bad = m;
  bad.voltage = kInf;
  EXPECT_EQ(est.update(bad), UpdateOutcome::skipped_nonfinite);
  bad = m;
  bad.t = kNan;
  EXPECT_EQ(est.update(bad), UpdateOutcome::skipped_nonfinite);
  bad = m;
  bad.tbar = 500.0;  // above tbar_max = 200
  EXPECT_EQ(est.update(bad), UpdateOutcome::skipped_range);
  bad = m;
  bad.x = -2.0;  // |x| > 1 m
  EXPECT_EQ(est.update(bad), UpdateOutcome::skipped_range);
  bad = m;
  bad.voltage = -150.0;
  EXPECT_EQ(est.update(bad), UpdateOutcome::skipped_range);
  bad = sample_at(499);  // time not advancing
  EXPECT_EQ(est.update(bad), UpdateOutcome::skipped_time);

  expect_same_state(est.state(), before);
  EXPECT_EQ(est.estimate().skipped_nonfinite, 3u);
  EXPECT_EQ(est.estimate().skipped_range, 3u);
  EXPECT_EQ(est.estimate().skipped_time, 1u);

  // The next good samples continue exactly as if the bad ones never came.
  for (int k = 500; k < 1000; ++k) {
    EXPECT_EQ(est.update(sample_at(k)), UpdateOutcome::applied);
    twin.update(sample_at(k));
  }
  expect_same_state(est.state(), twin.state());
  EXPECT_EQ(est.estimate().updates, twin.estimate().updates);
}

TEST(Estimator, ZeroRegressorLeavesEstimateUnchanged) {
  EstimatorConfig c = scaled_config();
  c.theta0 << 1000.0, 1.0, 1500.0, 0.2, 0.05, 1.0;
  Estimator est(c);
  // At rest, cold, no voltage: W = 0 and a = 0.
  for (int k = 0; k < 2000; ++k) {
    est.update(Measurement{.t = k * 1e-3, .x = 0.0, .xdot = 0.0, .tbar = 0.0, .voltage = 0.0});
  }
  EXPECT_EQ(est.estimate().theta_hat, c.theta0);
  EXPECT_EQ(est.estimate().updates, 1999u);
}

TEST(Estimator, LongGapRestartsFiltersAndKeepsWhatWasLearned) {
  Estimator est(scaled_config());
  for (int k = 0; k < 300; ++k) est.update(sample_at(k));
  const State before = est.state();
  EXPECT_EQ(est.update(sample_at(320)), UpdateOutcome::filters_restarted);  // 20 ms > 10 × 1 ms
  EXPECT_EQ(est.estimate().filter_restarts, 1u);
  EXPECT_EQ(est.state().theta_hat, before.theta_hat);
  EXPECT_EQ(est.state().info_mech, before.info_mech);
  EXPECT_EQ(est.filtered_regressor(), Regressor::Zero());
  EXPECT_EQ(est.update(sample_at(321)), UpdateOutcome::applied);
}

TEST(Estimator, RestoreRoundTrip) {
  Estimator est(scaled_config());
  for (int k = 0; k < 3000; ++k) est.update(sample_at(k));
  const State saved = est.state();

  Estimator other(scaled_config());
  ASSERT_TRUE(other.restore(saved));
  const State back = other.state();
  for (int i = 0; i < 6; ++i) EXPECT_DOUBLE_EQ(back.theta_hat(i), saved.theta_hat(i));
  EXPECT_TRUE(back.info_mech.isApprox(saved.info_mech, 1e-14));
  EXPECT_TRUE(back.info_thermal.isApprox(saved.info_thermal, 1e-14));
  EXPECT_EQ(back.eps2_mean, saved.eps2_mean);
  EXPECT_EQ(back.t, saved.t);
  // Restored estimator restarts its filters on the next sample, then runs on.
  EXPECT_EQ(other.update(sample_at(3001)), UpdateOutcome::initialized);
  EXPECT_EQ(other.update(sample_at(3002)), UpdateOutcome::applied);

  // A checkpoint survives a change of scale: θ̂ and R are stored in θ coordinates.
  Estimator unscaled(EstimatorConfig{});
  ASSERT_TRUE(unscaled.restore(saved));
  EXPECT_TRUE(unscaled.state().info_mech.isApprox(saved.info_mech, 1e-12));
  for (int i = 0; i < 6; ++i)
    EXPECT_NEAR(unscaled.state().theta_hat(i), saved.theta_hat(i),
                1e-15 * std::abs(saved.theta_hat(i)));
}

TEST(Estimator, RestoreRejectsBadStateWithoutChange) {
  Estimator est(scaled_config());
  for (int k = 0; k < 1000; ++k) est.update(sample_at(k));
  const State good = est.state();

  State s = good;
  s.theta_hat(2) = kNan;
  EXPECT_FALSE(est.restore(s));
  s = good;
  s.info_mech(1, 1) = -1.0;  // not positive definite
  EXPECT_FALSE(est.restore(s));
  s = good;
  s.info_thermal(0, 1) += 1.0;  // not symmetric
  EXPECT_FALSE(est.restore(s));
  s = good;
  s.info_thermal.setZero();  // singular
  EXPECT_FALSE(est.restore(s));
  s = good;
  s.eps2_mean(0) = kInf;
  EXPECT_FALSE(est.restore(s));
  s = good;
  s.t = kNan;
  EXPECT_FALSE(est.restore(s));

  expect_same_state(est.state(), good);
  EXPECT_EQ(est.update(sample_at(1000)), UpdateOutcome::applied);  // filters were not touched
}

void expect_rejected(EstimatorConfig c, const std::string& field) {
  try {
    Estimator est(c);
    ADD_FAILURE() << "config with bad " << field << " was accepted";
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(field + " ="), std::string::npos) << what;
    EXPECT_NE(what.find("allowed"), std::string::npos) << what;
  }
}

TEST(Estimator, ConstructorRejectsBadConfigNamingTheField) {
  EstimatorConfig c;
  c.beta = 0.0;
  expect_rejected(c, "beta");
  c = {};
  c.forgetting = -0.8;
  expect_rejected(c, "forgetting");
  c = {};
  c.p0 = kNan;
  expect_rejected(c, "p0");
  c = {};
  c.p0 = 1e13;  // above p_max
  expect_rejected(c, "p0");
  c = {};
  c.scale(3) = 0.0;
  expect_rejected(c, "scale[3]");
  c = {};
  c.theta0(5) = kInf;
  expect_rejected(c, "theta0[5]");
  c = {};
  c.nominal_period = 0.0;
  expect_rejected(c, "nominal_period");
  c = {};
  c.tbar_max = -5.0;
  expect_rejected(c, "tbar_max");
  c = {};
  c.max_gap_periods = 0.5;
  expect_rejected(c, "max_gap_periods");
  EXPECT_NO_THROW(Estimator{EstimatorConfig{}});
}

TEST(Estimator, ResetIsColdStart) {
  EstimatorConfig c = scaled_config();
  c.theta0 << 1.0, 2.0, 3.0, 4.0, 5.0, 6.0;
  Estimator est(c);
  const State fresh = est.state();
  for (int k = 0; k < 1000; ++k) est.update(sample_at(k));
  est.reset();
  expect_same_state(est.state(), fresh);
  EXPECT_EQ(est.estimate().updates, 0u);
  EXPECT_EQ(est.update(sample_at(5)), UpdateOutcome::initialized);
}

}  // namespace
}  // namespace scp::estimator

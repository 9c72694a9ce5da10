// The staged output-error fit on noise-free records: it must find θ to 1e-6 from bad starts.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "refine/fit.hpp"
#include "tests/refine/record.hpp"

namespace scp::refine {
namespace {

double max_relative_error(const Vector6& estimate, const Vector6& truth) {
  return ((estimate - truth).cwiseQuotient(truth)).cwiseAbs().maxCoeff();
}

class PaperRecord : public ::testing::Test {
 protected:
  const std::vector<WindowSample>* window_ = &test::cached_paper_record(300.0);
  const Vector6 truth_ = test::theta_of(test::paper_actuator());
};

TEST_F(PaperRecord, ConvergesFromThirtyPercentOff) {
  for (double sign : {1.0, -1.0}) {
    Vector6 start = truth_;
    for (int i = 0; i < 6; ++i) start[i] *= 1.0 + sign * (i % 2 == 0 ? 0.3 : -0.3);
    const FitResult r = fit(*window_, start);
    const double err = max_relative_error(r.theta, truth_);
    std::printf("±30 %% (sign %+g): %s after %d iterations, max rel error %.3g\n", sign, r.message,
                r.iterations, err);
    EXPECT_TRUE(r.converged) << r.message;
    EXPECT_LT(err, 1e-6);
  }
}

TEST_F(PaperRecord, ConvergesFromThePaperLawsBiasedStart) {
  Vector6 start = truth_;
  start.head<4>() *= 0.17;
  start[5] *= 1.001;
  const FitResult r = fit(*window_, start);
  const double err = max_relative_error(r.theta, truth_);
  std::printf("x0.17 start: %s after %d iterations, max rel error %.3g\n", r.message, r.iterations,
              err);
  EXPECT_TRUE(r.converged) << r.message;
  EXPECT_LT(err, 1e-6);
}

TEST_F(PaperRecord, ConvergesFromZero) {
  const FitResult r = fit(*window_, Vector6::Zero());
  const double err = max_relative_error(r.theta, truth_);
  std::printf("zero start: %s after %d iterations, max rel error %.3g\n", r.message, r.iterations,
              err);
  EXPECT_TRUE(r.converged) << r.message;
  EXPECT_LT(err, 1e-6);
}

}  // namespace
}  // namespace scp::refine

namespace scp::refine {
namespace {

TEST(Fit, UnderdampedFasterActuatorConvergesNoiseFree) {
  const auto params = test::underdamped_actuator();
  const Vector6 truth = test::theta_of(params);
  const auto w = test::paper_record(120.0, {}, params);
  for (double sign : {1.0, -1.0}) {
    Vector6 start = truth;
    for (int i = 0; i < 6; ++i) start[i] *= 1.0 + sign * (i % 2 == 0 ? 0.3 : -0.3);
    const FitResult r = fit(w, start);
    const double err = max_relative_error(r.theta, truth);
    std::printf("underdamped ±30 %% (sign %+g): %s after %d iterations, max rel error %.3g\n", sign,
                r.message, r.iterations, err);
    EXPECT_TRUE(r.converged) << r.message;
    EXPECT_LT(err, 1e-6);
  }
  const FitResult r = fit(w, Vector6::Zero());
  std::printf("underdamped zero start: %s, max rel error %.3g\n", r.message,
              max_relative_error(r.theta, truth));
  EXPECT_TRUE(r.converged) << r.message;
  EXPECT_LT(max_relative_error(r.theta, truth), 1e-6);
}

// The daemon's sliding window starts mid-experiment: hot, moving, x0 and T̄0 far from zero.
TEST(Fit, WindowStartingMidExperiment) {
  const auto& full = test::cached_paper_record(300.0);
  const std::vector<WindowSample> w(full.begin() + 100000, full.begin() + 200001);
  const Vector6 truth = test::theta_of(test::paper_actuator());
  Vector6 start = truth;
  start.head<4>() *= 0.17;
  const FitResult r = fit(w, start);
  std::printf("window 100..200 s: %s, max rel error %.3g, T0 %.6f (data %.6f)\n", r.message,
              max_relative_error(r.theta, truth), r.initial_state[2], w[0].tbar);
  EXPECT_TRUE(r.converged) << r.message;
  EXPECT_LT(max_relative_error(r.theta, truth), 1e-6);
  EXPECT_NEAR(r.initial_state[0], w[0].x, 1e-9 * std::abs(w[0].x));
  EXPECT_NEAR(r.initial_state[2], w[0].tbar, 1e-9 * w[0].tbar);
  EXPECT_DOUBLE_EQ(r.t_begin, 100.0);
  EXPECT_DOUBLE_EQ(r.t_end, 200.0);
  EXPECT_EQ(r.samples, 100001u);
}

TEST(Fit, KnownParametersAreHeldAndGetNoSigma) {
  const auto& w = test::cached_paper_record(60.0);
  const Vector6 truth = test::theta_of(test::paper_actuator());
  Vector6 start = truth * 1.2;
  start[2] = truth[2];  // θ3 = k/m known exactly
  FitSettings settings;
  settings.known[2] = true;
  const FitResult r = fit(w, start, settings);
  EXPECT_TRUE(r.converged) << r.message;
  EXPECT_EQ(r.theta[2], truth[2]);
  EXPECT_EQ(r.sigma[2], 0.0);
  EXPECT_LT(max_relative_error(r.theta, truth), 1e-6);
}

TEST(Fit, UnusableWindowsAreRefusedWithAReason) {
  const auto& good = test::cached_paper_record(60.0);
  const Vector6 truth = test::theta_of(test::paper_actuator());
  std::vector<WindowSample> w(good.begin(), good.begin() + 2);
  FitResult r = fit(w, truth);
  EXPECT_FALSE(r.converged);
  EXPECT_STREQ(r.message, "window has fewer than 3 samples");
  w.assign(good.begin(), good.begin() + 100);
  w[50].t = w[49].t;
  r = fit(w, truth);
  EXPECT_FALSE(r.converged);
  EXPECT_STREQ(r.message, "window times are not strictly increasing");
  w.assign(good.begin(), good.begin() + 100);
  w[10].x = std::nan("");
  r = fit(w, truth);
  EXPECT_FALSE(r.converged);
  EXPECT_STREQ(r.message, "window has a non-finite sample");
  // No heating at all: the thermal and mechanical blocks are not excited.
  w.assign(good.begin(), good.begin() + 1000);
  for (auto& s : w) s.voltage = 0.0, s.x = 0.0, s.tbar = 0.0;
  r = fit(w, truth);
  EXPECT_FALSE(r.converged);
  std::printf("unexcited window: %s\n", r.message);
}

TEST(Fit, NonUniformSamplingWithMidIntervalVoltage) {
  const auto params = test::paper_actuator();
  const Vector6 truth = test::theta_of(params);
  const auto w = test::link_record(params, 120.0);
  Vector6 start = truth * 1.2;
  const FitResult r = fit(w, start);
  std::printf("jittered 10 ms link, 120 s: %s, max rel error %.3g\n", r.message,
              max_relative_error(r.theta, truth));
  EXPECT_TRUE(r.converged) << r.message;
  EXPECT_LT(max_relative_error(r.theta, truth), 1e-6);
}

}  // namespace
}  // namespace scp::refine

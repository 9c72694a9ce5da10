// The voltage's timing (FitSettings::voltage_hold, voltage_interval; refine/voltage_timing.hpp)
// on noise-free records of the project's plant whose timing differs from WindowSample's
// convention: the fit must find θ to 1e-6 when told the timing, and choose it when asked to.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <vector>

#include "refine/fit.hpp"
#include "refine/parameters.hpp"
#include "refine/voltage_timing.hpp"
#include "tests/refine/record.hpp"
#include "tests/refine/timing_record.hpp"

namespace scp::refine {
namespace {

double max_relative_error(const Vector6& estimate, const Vector6& truth) {
  return ((estimate - truth).cwiseQuotient(truth)).cwiseAbs().maxCoeff();
}

Vector6 biased_start(const Vector6& truth) {
  Vector6 start = truth;
  start.head<4>() *= 0.6;
  start.tail<2>() *= 1.2;
  return start;
}

const std::vector<WindowSample>& logged_after() {
  static const auto w =
      test::record_logged_after(test::paper_actuator(), 120.0, 1e-3, test::paper_voltage());
  return w;
}

const std::vector<WindowSample>& ramped() {
  static const auto w =
      test::record_ramped(test::paper_actuator(), 120.0, 1e-3, test::smooth_voltage);
  return w;
}

const std::vector<WindowSample>& continuous() {
  static const auto w =
      test::record_continuous(test::paper_actuator(), 120.0, 1e-3, test::smooth_voltage);
  return w;
}

TEST(PrepareWindow, MovesEachVoltageToTheIntervalItDrove) {
  const std::vector<WindowSample> w{
      {0.0, 0, 0, 1.0, -1e300}, {1.0, 0, 0, 2.0, -1e300}, {3.0, 0, 0, 4.0, -1e300}};
  std::vector<WindowSample> storage;
  const auto same =
      prepare_window(w, estimator::VoltageHold::zoh, VoltageInterval::before, storage);
  EXPECT_EQ(same.data(), w.data());
  const auto after =
      prepare_window(w, estimator::VoltageHold::zoh, VoltageInterval::after, storage);
  ASSERT_EQ(after.size(), 3U);
  EXPECT_EQ(after[1].voltage, 1.0);
  EXPECT_EQ(after[1].voltage_since, 0.0);
  EXPECT_EQ(after[2].voltage, 2.0);
  EXPECT_EQ(after[2].voltage_since, 1.0);
  const auto foh = prepare_window(w, estimator::VoltageHold::foh, VoltageInterval::before, storage);
  EXPECT_FALSE(foh[0].voltage_ramp);
  EXPECT_TRUE(foh[1].voltage_ramp);
  EXPECT_TRUE(foh[2].voltage_ramp);
  EXPECT_EQ(foh[2].voltage, 4.0);
}

TEST(VoltageTiming, AHeldVoltageLoggedAfterIsFitToOneInAMillion) {
  const Vector6 truth = test::theta_of(test::paper_actuator());
  FitSettings settings;
  settings.voltage_interval = VoltageInterval::after;
  const FitResult r = fit(logged_after(), biased_start(truth), settings);
  const double err = max_relative_error(r.theta, truth);
  std::printf("held V logged after, told: %s, max rel error %.3g\n", r.message, err);
  EXPECT_TRUE(r.converged) << r.message;
  EXPECT_EQ(r.voltage_interval, VoltageInterval::after);
  EXPECT_LT(err, 1e-6);
}

TEST(VoltageTiming, TheIntervalIsChosenByTheData) {
  const Vector6 truth = test::theta_of(test::paper_actuator());
  FitSettings settings;
  settings.voltage_interval = VoltageInterval::estimate;
  const FitResult after = fit(logged_after(), biased_start(truth), settings);
  std::printf("held V logged after, estimated: %s (%s), max rel error %.3g\n", after.message,
              to_text(after.voltage_interval), max_relative_error(after.theta, truth));
  EXPECT_EQ(after.voltage_interval, VoltageInterval::after);
  EXPECT_TRUE(after.converged) << after.message;
  EXPECT_LT(max_relative_error(after.theta, truth), 1e-6);
  const FitResult before = fit(test::cached_paper_record(120.0), biased_start(truth), settings);
  std::printf("held V logged before, estimated: %s (%s), max rel error %.3g\n", before.message,
              to_text(before.voltage_interval), max_relative_error(before.theta, truth));
  EXPECT_EQ(before.voltage_interval, VoltageInterval::before);
  EXPECT_LT(max_relative_error(before.theta, truth), 1e-6);
}

// The daemon's settings on a link (refine.link_timing: estimate) with its default 5 ms delay limit
// on noise-free 1 kHz records: a delay beyond the interval is a plateau of the model (every switch
// held at its interval's end), which the search once wandered onto ("could not be estimated (no
// heating?)", σ = 0). A held V logged after its interval is the delay of one whole period.
TEST(VoltageTiming, TheDelayIsEstimatedOnNoiseFreeRecordsWithALimitBeyondOnePeriod) {
  const Vector6 truth = test::theta_of(test::paper_actuator());
  FitSettings settings;
  settings.max_input_delay_s = 5e-3;
  settings.sample_timing_jitter = true;
  settings.outlier_threshold = kOutlierThreshold2d;
  settings.landing_timing_jitter = true;
  struct Case {
    const char* what;
    const std::vector<WindowSample>* window;
    double delay;
  };
  for (const Case& c : {Case{"logged before", &test::cached_paper_record(120.0), 0.0},
                        Case{"logged after", &logged_after(), 1e-3}}) {
    const FitResult r = fit(*c.window, biased_start(truth), settings);
    std::printf("%s, delay estimated: %s, d = %.3g s (σ %.2g), max rel error %.3g\n", c.what,
                r.message, r.input_delay_s, r.input_delay_sigma_s,
                max_relative_error(r.theta, truth));
    EXPECT_TRUE(r.converged) << c.what << ": " << r.message;
    EXPECT_TRUE(r.input_delay_estimated) << c.what;
    EXPECT_NEAR(r.input_delay_s, c.delay, 1e-8) << c.what;
    EXPECT_LT(max_relative_error(r.theta, truth), 1e-6) << c.what;
  }
}

void print_errors(const char* what, const FitResult& r, const Vector6& truth) {
  std::printf("%s: %s, relative errors", what, r.message);
  for (int i = 0; i < 6; ++i) std::printf(" %.2g", r.theta[i] / truth[i] - 1.0);
  std::printf("\n");
}

TEST(VoltageTiming, ARampingDacIsFitWithFirstOrderHoldToOneInAMillion) {
  const Vector6 truth = test::theta_of(test::paper_actuator());
  FitSettings settings;
  settings.voltage_hold = estimator::VoltageHold::foh;
  const FitResult r = fit(ramped(), biased_start(truth), settings);
  print_errors("ramping DAC, foh", r, truth);
  EXPECT_TRUE(r.converged) << r.message;
  EXPECT_LT(max_relative_error(r.theta, truth), 1e-6);
}

// A continuous V read as smooth between samples (the cubic through four rows): V² exact to
// O(τ⁴·V''''), θ to one in a million. Read as linear, the chord's error V''·τ²/8 leaves θ1..θ4's
// common scale (a sub-millisecond lag) off by ~1e-4 on this slow voltage, growing as (ωτ)² with
// faster content (docs/numerics.md, "The voltage's timing"); a held V would be off by half a
// period.
TEST(VoltageTiming, AContinuousVoltageIsFitWithFirstOrderHold) {
  const Vector6 truth = test::theta_of(test::paper_actuator());
  FitSettings settings;
  settings.voltage_hold = estimator::VoltageHold::foh;
  settings.voltage_shape = VoltageShape::smooth;
  const FitResult r = fit(continuous(), biased_start(truth), settings);
  print_errors("continuous V, foh, smooth", r, truth);
  EXPECT_TRUE(r.converged) << r.message;
  const double err = max_relative_error(r.theta, truth);
  EXPECT_LT(err, 1e-6);
  settings.voltage_shape = VoltageShape::linear;
  const FitResult chord = fit(continuous(), biased_start(truth), settings);
  print_errors("continuous V, foh, linear", chord, truth);
  EXPECT_GT(max_relative_error(chord.theta, truth), 100 * err);
  EXPECT_LT(std::abs(r.theta[kCooling] / truth[kCooling] - 1.0), 1e-6);
  EXPECT_LT(std::abs(r.theta[kHeating] / truth[kHeating] - 1.0), 1e-6);
  const FitResult held = fit(continuous(), biased_start(truth));
  print_errors("continuous V, zoh", held, truth);
  EXPECT_GT(max_relative_error(held.theta, truth), 100 * err);
}

}  // namespace
}  // namespace scp::refine

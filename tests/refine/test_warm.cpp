// The warm refit (refine/warm_start.hpp) on 310 s records of the project's RK4 plant (drivers/sim,
// not the fit's discretization) with N1 noise and a bench's nuisance terms: the window 10 s later,
// refitted from the earlier window's solution shifted along its trajectory, lands where the full
// fit of the same window lands (within 0.1 σ) in a few passes, and it gives way to the full fit
// when it does not apply.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <span>
#include <vector>

#include "drivers/sim/plant.hpp"
#include "refine/fit.hpp"
#include "refine/warm_start.hpp"
#include "tests/refine/record.hpp"

namespace scp::refine {
namespace {

constexpr double kSeconds = 310.0, kWindow = 300.0, kStep = 10.0;
constexpr std::size_t kPerSecond = 1000;

// The plant with a displacement zero and a drifting room, V held over each interval and recorded
// at the end of it (voltage_since = the previous sample); N1 noise.
std::vector<WindowSample> bench_record(unsigned seed) {
  drivers::sim::PlantDeviations d;
  d.ambient_offset_c = 1.0;
  d.ambient_drift_c_per_h = 2.0;
  drivers::sim::Plant plant(test::paper_actuator(), 20, {}, d);
  const auto voltage = test::paper_voltage();
  const auto n = static_cast<std::size_t>(kSeconds * kPerSecond) + 1;
  std::vector<WindowSample> w;
  w.reserve(n);
  double v_prev = 0.0;
  for (std::size_t k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) / kPerSecond;
    w.push_back({t, plant.x() + 50e-6, plant.sensed_tbar(), v_prev, t - 1e-3});
    v_prev = voltage(t);
    plant.step(v_prev, 1e-3);
  }
  return test::with_noise(w, {.x = 1e-7, .tbar = 1e-3, .seed = seed});
}

// The same record as a log that writes each command at the instant it was issued.
std::vector<WindowSample> logged_after(std::vector<WindowSample> w) {
  for (std::size_t k = 0; k + 1 < w.size(); ++k) {
    w[k].voltage = w[k + 1].voltage;
    w[k].voltage_since = -1e300;
  }
  return w;
}

FitSettings estimating(VoltageInterval interval = VoltageInterval::before) {
  FitSettings s;
  s.nuisance.x_zero.fixed = s.nuisance.ambient_offset.fixed = s.nuisance.ambient_drift.fixed =
      false;
  s.voltage_interval = interval;
  return s;
}

struct Windows {
  std::span<const WindowSample> first, second;  // [0, 300] s and [10, 310] s
};
Windows windows(const std::vector<WindowSample>& w) {
  const std::size_t n = static_cast<std::size_t>(kWindow * kPerSecond) + 1;
  const std::size_t shift = static_cast<std::size_t>(kStep * kPerSecond);
  return {std::span(w).subspan(0, n), std::span(w).subspan(shift, n)};
}

// The warm start of `fit` (made on `w` from its first sample) shifted to sample `to`.
WarmStart shifted(const FitResult& fit, const FitSettings& settings,
                  const std::vector<WindowSample>& w, std::size_t to) {
  WarmStart warm = warm_start(fit, settings, w.front());
  for (std::size_t k = 0; k < to; ++k) shift(warm, w[k], w[k + 1]);
  return warm;
}

Vector6 start() {
  Vector6 s = test::theta_of(test::paper_actuator());
  s.head<4>() *= 0.8;
  return s;
}

void expect_warm_equals_cold(const std::vector<WindowSample>& w, const FitSettings& settings) {
  const Windows win = windows(w);
  const FitResult first = fit(win.first, start(), settings);
  ASSERT_TRUE(first.converged) << first.message;
  const WarmStart warm = shifted(first, settings, w, static_cast<std::size_t>(kStep * kPerSecond));
  FitSettings with_warm = settings;
  with_warm.warm = &warm;
  const FitResult hot = fit(win.second, first.theta, with_warm);
  const FitResult cold = fit(win.second, first.theta, settings);
  std::printf("cold: %d iterations, %d passes; warm: %d iterations, %d passes (%s)\n",
              cold.iterations, cold.evaluations, hot.iterations, hot.evaluations,
              to_text(hot.warm_fallback));
  EXPECT_TRUE(hot.warm) << to_text(hot.warm_fallback);
  EXPECT_EQ(hot.warm_fallback, WarmFallback::none);
  EXPECT_FALSE(cold.warm);
  EXPECT_EQ(cold.warm_fallback, WarmFallback::not_requested);
  ASSERT_TRUE(hot.converged) << hot.message;
  ASSERT_TRUE(cold.converged) << cold.message;
  EXPECT_LT(hot.evaluations, cold.evaluations / 4);
  std::printf("warm − cold in σ:");
  for (int i = 0; i < 6; ++i) {
    const double z = (hot.theta[i] - cold.theta[i]) / cold.sigma[i];
    std::printf(" %.3f", z);
    EXPECT_LT(std::abs(z), 0.1) << i;
    EXPECT_NEAR(hot.sigma[i] / cold.sigma[i], 1.0, 0.05) << i;
  }
  std::printf("\n");
  EXPECT_LT(std::abs(hot.nuisance.x_zero.value - cold.nuisance.x_zero.value),
            0.1 * cold.nuisance.x_zero.sigma);
  EXPECT_LT(std::abs(hot.nuisance.ambient_offset.value - cold.nuisance.ambient_offset.value),
            0.1 * cold.nuisance.ambient_offset.sigma);
  EXPECT_EQ(hot.voltage_interval, cold.voltage_interval);
}

TEST(WarmRefit, EqualsTheFullFitTenSecondsLater) {
  expect_warm_equals_cold(bench_record(11), estimating());
}

// A log of the command at its instant: each row's voltage is moved to the next interval, and the
// trajectory carried between the windows must read the rows the same way.
TEST(WarmRefit, EqualsTheFullFitOnAVoltageLoggedAfter) {
  expect_warm_equals_cold(logged_after(bench_record(12)), estimating(VoltageInterval::after));
}

class Fallback : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    record_ = new std::vector<WindowSample>(bench_record(13));
    first_ = new FitResult(fit(windows(*record_).first, start(), estimating()));
  }
  static void TearDownTestSuite() {
    delete record_;
    delete first_;
  }
  WarmStart warm() const {
    return shifted(*first_, estimating(), *record_, static_cast<std::size_t>(kStep * kPerSecond));
  }
  std::span<const WindowSample> second() const { return windows(*record_).second; }
  static std::vector<WindowSample>* record_;
  static FitResult* first_;
};
std::vector<WindowSample>* Fallback::record_ = nullptr;
FitResult* Fallback::first_ = nullptr;

TEST_F(Fallback, WhenTheSettingsChanged) {
  FitSettings other = estimating();
  other.nuisance.ambient_drift.fixed = true;
  EXPECT_EQ(refit(second(), warm(), other).warm_fallback, WarmFallback::settings_changed);
  other = estimating();
  other.covariance_batches = 10;
  EXPECT_EQ(refit(second(), warm(), other).warm_fallback, WarmFallback::settings_changed);
}

TEST_F(Fallback, WhenThePreviousFitDidNotConverge) {
  WarmStart w = warm();
  w.converged = false;
  EXPECT_EQ(refit(second(), w, estimating()).warm_fallback, WarmFallback::not_converged_before);
}

// The daemon steps the warm start of every fit along its window, converged or not (the refit
// then says why it declined); one that did not converge, or whose model overflowed, is left where
// it is: its refit is declined the same, and an unstable model's simulation costs libm's overflow
// path at every sample.
TEST_F(Fallback, AWarmStartThatCannotApplyIsNotStepped) {
  WarmStart w = warm_start(*first_, estimating(), record_->front());
  w.converged = false;
  const WarmStart before = w;
  shift(w, (*record_)[0], (*record_)[1]);
  EXPECT_EQ(w.at.t, before.at.t);
  EXPECT_EQ(w.state, before.state);
  w.converged = true;
  w.state[2] = std::numeric_limits<double>::infinity();
  shift(w, (*record_)[0], (*record_)[1]);
  EXPECT_EQ(w.at.t, before.at.t);
  w.state = before.state;
  shift(w, (*record_)[0], (*record_)[1]);
  EXPECT_EQ(w.at.t, (*record_)[1].t);
  EXPECT_NE(w.state, before.state);
}

TEST_F(Fallback, WhenTheTrajectoryIsNotAtTheWindowsStart) {
  // Not shifted: the state is at the first window's start, 10 s before the second's.
  const WarmStart unshifted = warm_start(*first_, estimating(), record_->front());
  EXPECT_EQ(refit(second(), unshifted, estimating()).warm_fallback, WarmFallback::no_overlap);
  // A window that starts after the previous one ended.
  WarmStart w = warm();
  w.t_end = second().front().t - 1.0;
  EXPECT_EQ(refit(second(), w, estimating()).warm_fallback, WarmFallback::no_overlap);
}

// A window over twice the previous fit's (as one growing from the daemon's start): the voltage's
// interval and switches and `auto`'s choices, kept by a warm refit, are made again.
TEST_F(Fallback, WhenTheWindowHasMoreThanDoubled) {
  WarmStart w = warm();
  const double span = second().back().t - second().front().t;
  w.t_begin = w.t_end - 0.49 * span;
  EXPECT_EQ(refit(second(), w, estimating()).warm_fallback, WarmFallback::window_grown);
  w.t_begin = w.t_end - 0.51 * span;
  EXPECT_NE(refit(second(), w, estimating()).warm_fallback, WarmFallback::window_grown);
}

TEST_F(Fallback, WhenTheStartIsFarFromTheSolution) {
  WarmStart w = warm();
  w.theta.head<4>() *= 0.3;  // the common scale of θ1..θ4 far off: not a few iterations away
  const FitResult r = refit(second(), w, estimating());
  std::printf("θ1..θ4 × 0.3: %s after %d iterations, %d passes\n", to_text(r.warm_fallback),
              r.iterations, r.evaluations);
  EXPECT_FALSE(r.warm);
  EXPECT_TRUE(r.warm_fallback == WarmFallback::not_converged ||
              r.warm_fallback == WarmFallback::verdict_failed)
      << to_text(r.warm_fallback);
}

// fit() with a warm start that does not apply runs the full fit and says why.
TEST_F(Fallback, FitRunsTheFullFitAndSaysWhy) {
  const WarmStart unshifted = warm_start(*first_, estimating(), record_->front());
  FitSettings s = estimating();
  s.warm = &unshifted;
  const FitResult r = fit(second(), first_->theta, s);
  EXPECT_FALSE(r.warm);
  EXPECT_EQ(r.warm_fallback, WarmFallback::no_overlap);
  EXPECT_TRUE(r.converged) << r.message;
  const FitResult cold = fit(second(), first_->theta, estimating());
  for (int i = 0; i < 6; ++i) EXPECT_EQ(r.theta[i], cold.theta[i]) << i;
}

}  // namespace
}  // namespace scp::refine

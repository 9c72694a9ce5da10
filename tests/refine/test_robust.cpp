// The fit always ends, whatever the data and the start: bounded work, non-finite trials rejected,
// a cancel flag honoured. Regression for the light-stiff Monte Carlo runs that hung in the
// refinement (bench/montecarlo.md, 2026-11-23): from the paper law's collapsed estimate on a short
// noisy window the common scale of θ1..θ4 is not determined, Levenberg–Marquardt followed the flat
// valley toward m → 0, and every pass grew slower with the stiffness (sub-steps ∝ θ1). Before the
// fix the 10 s window below did not finish in minutes; ctest's TIMEOUT on this program (60 s) fails
// it fast if that comes back.

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <thread>

#include "tests/refine/light_stiff.hpp"
#include "tests/refine/record.hpp"

namespace scp::refine {
namespace {

using test::light_stiff;
using test::light_stiff_collapsed_start;
using test::light_stiff_voltage;

// 10 s of the light-stiff actuator at 1 kHz under the paper's voltage with issue 8's N2 noise.
const std::vector<WindowSample>& hard_window() {
  static const std::vector<WindowSample> w = test::record(
      light_stiff(), 10.0, 1e-3, test::paper_voltage(), {.x = 1e-6, .tbar = 1e-2, .seed = 3});
  return w;
}

TEST(FitRobustness, AnUnidentifiableScaleEndsWithinTheBudget) {
  const FitSettings settings;
  const FitResult r = fit(hard_window(), light_stiff_collapsed_start(), settings);
  EXPECT_LE(r.evaluations, settings.max_evaluations + 1);  // + the covariance pass
  EXPECT_TRUE(r.theta.allFinite());
  EXPECT_GT(std::strlen(r.message), 0U);
  // Whatever it says, it may not claim a scale whose inertia the samples cannot show.
  if (r.converged) {
    const double rho =
        std::abs(r.theta[0]) + 100.0 * std::abs(r.theta[1]) + std::sqrt(std::abs(r.theta[2]));
    EXPECT_LT(rho * 1e-3, 20.0) << r.message;
  }
}

TEST(FitRobustness, AnEvaluationBudgetStopsTheFitNotConverged) {
  FitSettings settings;
  settings.max_evaluations = 15;
  const FitResult r = fit(hard_window(), light_stiff_collapsed_start(), settings);
  EXPECT_FALSE(r.converged);
  EXPECT_LE(r.evaluations, 15);
  EXPECT_NE(std::strstr(r.message, "budget"), nullptr) << r.message;
  EXPECT_TRUE(r.theta.allFinite());
}

TEST(FitRobustness, ACancelFlagSetBeforehandStopsAtOnce) {
  std::atomic<bool> cancel{true};
  FitSettings settings;
  settings.cancel = &cancel;
  const FitResult r = fit(hard_window(), light_stiff_collapsed_start(), settings);
  EXPECT_FALSE(r.converged);
  EXPECT_STREQ(r.message, "cancelled");
  EXPECT_LE(r.evaluations, 1);
}

TEST(FitRobustness, ACancelFlagSetDuringTheFitStopsIt) {
  std::atomic<bool> cancel{false};
  FitSettings settings;
  settings.cancel = &cancel;
  std::thread canceller([&cancel] {
    std::this_thread::sleep_for(std::chrono::milliseconds(30));
    cancel.store(true);
  });
  const FitResult r = fit(hard_window(), light_stiff_collapsed_start(), settings);
  canceller.join();
  EXPECT_FALSE(r.converged);
  EXPECT_STREQ(r.message, "cancelled");
}

TEST(FitRobustness, ANonFiniteStartIsReplacedAndTheFitEnds) {
  Vector6 start = light_stiff_collapsed_start();
  start[0] = std::numeric_limits<double>::quiet_NaN();
  start[4] = std::numeric_limits<double>::infinity();
  FitSettings settings;
  settings.max_evaluations = 40;  // enough to show it runs; the window is unidentifiable anyway
  const FitResult r = fit(hard_window(), start, settings);
  EXPECT_TRUE(r.theta.allFinite());
  EXPECT_GT(std::strlen(r.message), 0U);
}

// Experiment design (docs/montecarlo.md): on light-stiff's own voltage (a PRBS with 1 s bits on the
// paper's slow sine, config/actuators/light-stiff.yaml) the data fix the common scale of θ1..θ4,
// and the fit from the paper law's collapsed estimate lands within a few Cramér–Rao σ at N2, where
// the paper's voltage left far minima on the stiff side (Monte Carlo N2 seed 3: +6200 %).
TEST(FitRobustness, LightStiffOnItsOwnExcitationLandsWithinItsBoundFromTheCollapsedStart) {
  const auto p = light_stiff();
  const Vector6 theta = test::theta_of(p);
  const auto clean = test::record(p, 30.0, 1e-3, light_stiff_voltage());
  const auto noisy = test::with_noise(clean, {.x = 1e-6, .tbar = 1e-2, .seed = 3});
  const FitResult r = fit(noisy, light_stiff_collapsed_start());
  ASSERT_TRUE(r.converged) << r.message;
  const InitialState x0(clean.front().x, 0.0, clean.front().tbar);
  const Matrix6 crb = cramer_rao_bound(clean, theta, x0, Vector2(1e-6, 1e-2));
  for (int i = 0; i < 6; ++i) {
    const double bound = std::sqrt(crb(i, i));
    std::printf("theta%d: error %.3g, CRB sigma %.3g, fit sigma %.3g (relative)\n", i + 1,
                (r.theta[i] - theta[i]) / theta[i], bound / theta[i], r.sigma[i] / theta[i]);
    EXPECT_LE(std::abs(r.theta[i] - theta[i]), 4.0 * bound) << "theta" << i + 1;
    EXPECT_LT(r.sigma[i], 2.0 * bound) << "theta" << i + 1;
  }
  EXPECT_LT(std::sqrt(crb(2, 2)) / theta[2], 0.1);  // this window does fix the scale
}

}  // namespace
}  // namespace scp::refine

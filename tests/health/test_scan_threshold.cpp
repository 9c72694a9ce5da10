// The crossing rate of a χ² process observed on overlapping windows: its limits, and a short
// simulation of moving windows against the formula (the long sweep is
// bench/bench_health_calibration.cpp).
#include <gtest/gtest.h>

#include <cmath>

#include "health/distributions.hpp"
#include "health/scan_threshold.hpp"
#include "tests/health/moving_window.hpp"

namespace scp::health {
namespace {

TEST(ScanThreshold, DiscreteCorrectionHasItsKnownShape) {
  EXPECT_NEAR(siegmund_nu(0.0), 1.0, 1e-12);
  for (double x : {0.05, 0.2, 0.5}) EXPECT_NEAR(siegmund_nu(x) / std::exp(-0.583 * x), 1.0, 0.02);
  EXPECT_LT(siegmund_nu(3.0), siegmund_nu(1.0));
}

TEST(ScanThreshold, NeverMoreThanIndependentTests) {
  // Tests a whole window apart are independent: the rate is then each test's tail per spacing.
  for (int dof : {1, 2, 4}) {
    const double b = 20.0;
    EXPECT_LE(chi_square_scan_rate(b, dof, 1.0 / 300.0, 300.0),
              chi_square_upper_tail(b, dof) / 300.0 * (1.0 + 1e-12));
  }
  // And denser tests of the same process never alarm less often.
  EXPECT_GT(chi_square_scan_threshold(1e-6, 4, 1.0 / 300.0, 10.0),
            chi_square_scan_threshold(1e-6, 4, 1.0 / 300.0, 300.0));
  const double b = chi_square_scan_threshold(1e-7, 2, 1.0 / 300.0, 10.0);
  EXPECT_NEAR(chi_square_scan_rate(b, 2, 1.0 / 300.0, 10.0) / 1e-7, 1.0, 1e-6);
}

TEST(ScanThreshold, SimulatedMovingWindowsCrossAtTheDesignedRate) {
  // 30 chunks per window (300 s refitted every 10 s); 4e5 steps at a designed 1/2000 per step:
  // ~200 alarms, a Poisson count within ±14 % at 2σ; the formula is asymptotic in b and was
  // measured within 13 % of 3e7-step runs at these levels.
  for (int dof : {1, 2, 4}) {
    const double rate = 1.0 / 2000.0;
    const double b = chi_square_scan_threshold(rate, dof, 1.0 / 30.0, 1.0);
    const double measured = test::moving_window_alarm_rate(dof, 30, b, 400000, 11 + dof);
    EXPECT_NEAR(measured / rate, 1.0, 0.3) << "dof " << dof << " b " << b;
  }
}

}  // namespace
}  // namespace scp::health

// Unit test of the stuck-sensor check (safety.stuck_timeout_s), daemon/core/safety.hpp.

#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "daemon/core/safety.hpp"

namespace scp::daemon {
namespace {

drivers::Sample reading(double x, double temperature) {
  drivers::Sample s;
  s.x = x;
  s.temperature = temperature;
  return s;
}

// Feeds the same reading every millisecond from t0 on; returns the loop time of the first
// refusal, or -1 if none within `seconds`.
double first_refusal(StuckDetector& d, const drivers::Sample& s, double t0, double seconds,
                     bool output_on, double timeout, Reason& why) {
  for (int k = 0; k <= static_cast<int>(seconds * 1000.0); ++k) {
    const double t = t0 + k * 1e-3;
    if (!d.update(s, t, output_on, timeout, why)) return t;
  }
  return -1.0;
}

TEST(StuckDetector, RepeatedReadingWithOutputOnFaultsAfterTheTimeout) {
  StuckDetector d;
  Reason why{};
  const double at = first_refusal(d, reading(1e-3, 30.0), 0.0, 2.0, true, 0.5, why);
  EXPECT_NEAR(at, 0.5, 1.5e-3);  // not earlier than the timeout, within a period after it
  const std::string text(why.data());
  EXPECT_NE(text.find("sensor stuck: x and T unchanged for 0.5 s"), std::string::npos) << text;
  EXPECT_NE(text.find("safety.stuck_timeout_s"), std::string::npos) << text;
}

TEST(StuckDetector, ChangingReadingsNeverFault) {
  StuckDetector d;
  Reason why{};
  for (int k = 0; k < 3000; ++k) {
    // Only the last bit of T changes every other sample: still alive.
    const double temperature = k % 2 ? std::nextafter(30.0, 31.0) : 30.0;
    ASSERT_TRUE(d.update(reading(1e-3, temperature), k * 1e-3, true, 0.5, why)) << k;
  }
  StuckDetector x_only;  // x moves, T constant: alive (both must repeat)
  for (int k = 0; k < 3000; ++k) {
    ASSERT_TRUE(x_only.update(reading(k * 1e-6, 30.0), k * 1e-3, true, 0.5, why)) << k;
  }
}

TEST(StuckDetector, ZeroVoltsOrDisabledNeverFaults) {
  StuckDetector d;
  Reason why{};
  EXPECT_LT(first_refusal(d, reading(0.0, 25.0), 0.0, 3.0, false, 0.5, why), 0.0)
      << "a resting actuator at 0 V legitimately reads constant values";
  StuckDetector off;
  EXPECT_LT(first_refusal(off, reading(0.0, 25.0), 0.0, 3.0, true, 0.0, why), 0.0);
}

TEST(StuckDetector, TimerRestartsWhenTheOutputComesOnOrTheReadingChanges) {
  StuckDetector d;
  Reason why{};
  const auto s = reading(2e-3, 40.0);
  for (int k = 0; k < 1000; ++k) ASSERT_TRUE(d.update(s, k * 1e-3, false, 0.5, why));
  // Output on at t = 1 s: the 0.5 s count starts there, not at t = 0.
  EXPECT_NEAR(first_refusal(d, s, 1.0, 2.0, true, 0.5, why), 1.5, 1.5e-3);
  d.reset();
  EXPECT_TRUE(d.update(s, 10.0, true, 0.5, why));
  EXPECT_TRUE(d.update(reading(2e-3, 40.5), 10.4, true, 0.5, why));
  EXPECT_TRUE(d.update(reading(2e-3, 40.5), 10.8, true, 0.5, why));  // 0.4 s since the change
  EXPECT_FALSE(d.update(reading(2e-3, 40.5), 10.95, true, 0.5, why));
}

}  // namespace
}  // namespace scp::daemon

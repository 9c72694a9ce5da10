#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "excitation/excitation.hpp"

namespace scp::excitation {
namespace {

std::string error_of(const ExcitationSettings& s) {
  try {
    Excitation e(s);
  } catch (const std::invalid_argument& ex) {
    return ex.what();
  }
  return "";
}

TEST(Excitation, PaperVoltageAtHandComputedInstants) {
  const Excitation e(paper_excitation());
  // t = 0: 1.6 + 0.4·(−1 + 0 + 0 − 1).
  EXPECT_NEAR(e.voltage(0.0), 0.8, 1e-12);
  // t = 2.5: fast terms sin(π/2) = 1 and sin(0) = 0; slow phase 0.03π:
  // 1.6 + 0.4·(−cos(0.03π) + sin(0.03π) + 1) = 1.6 + 0.4·(−0.99556196 + 0.09410831 + 1).
  EXPECT_NEAR(e.voltage(2.5), 1.6394185394861738, 1e-12);
  // t = 250/6 s: slow phase π/2 (terms 0 and 1), fast phase 25π/3 ≡ π/3 (terms √3/2, −1/2).
  EXPECT_NEAR(e.voltage(250.0 / 6.0), 1.6 + 0.4 * (1.0 + std::sqrt(3.0) / 2.0 - 0.5), 1e-12);
  // Bounds: 0 ≤ V ≤ 3.2 over a full slow period (1/0.006 s ≈ 167 s).
  for (double t = 0; t < 170.0; t += 0.01) {
    const double v = e.voltage(t);
    ASSERT_GE(v, 0.0);
    ASSERT_LE(v, 3.2);
  }
}

TEST(Excitation, ClampsAndRejectsNonFiniteTime) {
  ExcitationSettings s;
  s.offset = 5.0;
  EXPECT_EQ(Excitation(s).voltage(1.0), 3.2);
  s.offset = -1.0;
  EXPECT_EQ(Excitation(s).voltage(1.0), 0.0);
  s.offset = 1.0;
  s.sines = {{3.0, 1.0, 0.0}};
  const Excitation e(s);
  EXPECT_EQ(e.voltage(0.25), 3.2);  // 1 + 3 = 4 → 3.2
  EXPECT_EQ(e.voltage(0.75), 0.0);  // 1 − 3 = −2 → 0
  EXPECT_EQ(e.voltage(std::numeric_limits<double>::quiet_NaN()), 0.0);
  EXPECT_EQ(e.voltage(std::numeric_limits<double>::infinity()), 0.0);
}

TEST(Excitation, StepsAddFromTheirTimeOn) {
  ExcitationSettings s;
  s.offset = 1.0;
  s.steps = {{2.0, 0.5}, {4.0, -0.25}};
  const Excitation e(s);
  EXPECT_EQ(e.voltage(0.0), 1.0);
  EXPECT_EQ(e.voltage(1.999), 1.0);
  EXPECT_EQ(e.voltage(2.0), 1.5);
  EXPECT_EQ(e.voltage(3.999), 1.5);
  EXPECT_EQ(e.voltage(4.0), 1.25);
  EXPECT_EQ(e.voltage(100.0), 1.25);
}

// Samples one value per bit, in the middle of each bit.
std::vector<int> prbs_bits(const Excitation& e, double bit_period, int count, double offset) {
  std::vector<int> bits;
  for (int i = 0; i < count; ++i) {
    const double v = e.voltage((i + 0.5) * bit_period);
    EXPECT_TRUE(std::abs(v - offset) > 0.0);
    bits.push_back(v > offset ? 1 : 0);
  }
  return bits;
}

TEST(Excitation, PrbsHasMaximalPeriodAndBalance) {
  for (int order : {4, 5, 7}) {
    ExcitationSettings s;
    s.offset = 1.0;
    s.prbs.amplitude = 0.5;
    s.prbs.bit_period_s = 0.1;
    s.prbs.order = order;
    s.prbs.seed = 5;
    const Excitation e(s);
    const int period = (1 << order) - 1;
    const std::vector<int> bits = prbs_bits(e, 0.1, 2 * period, 1.0);
    // Levels are exactly offset ± amplitude.
    EXPECT_NEAR(e.voltage(0.05), bits[0] ? 1.5 : 0.5, 1e-15);
    int ones = 0;
    for (int i = 0; i < period; ++i) {
      ones += bits[i];
      ASSERT_EQ(bits[i], bits[i + period]) << "order " << order << " bit " << i;
    }
    EXPECT_EQ(ones, 1 << (order - 1)) << order;  // one more high bit than low bits
    // No shorter period.
    for (int p = 1; p < period; ++p) {
      bool same = true;
      for (int i = 0; i < period && same; ++i) same = bits[i] == bits[i + p];
      EXPECT_FALSE(same) << "order " << order << " repeats after " << p;
    }
    // An m-sequence's longest run of ones is `order` bits.
    int run = 0, longest = 0;
    for (int b : bits) {
      run = b ? run + 1 : 0;
      longest = std::max(longest, run);
    }
    EXPECT_EQ(longest, order);
  }
}

TEST(Excitation, PrbsDeterministicAndIndependentOfCallPattern) {
  ExcitationSettings s;
  s.offset = 1.0;
  s.prbs.amplitude = 0.5;
  s.prbs.bit_period_s = 0.01;
  s.prbs.order = 9;
  const Excitation dense(s), sparse(s), other_seed([&] {
    ExcitationSettings o = s;
    o.prbs.seed = 99;
    return o;
  }());
  std::vector<double> d;
  for (int k = 0; k < 20000; ++k) d.push_back(dense.voltage(k * 1e-3));
  // Querying only every 37th instant (skipping bits), then going back in time, agrees.
  for (int k = 0; k < 20000; k += 37) ASSERT_EQ(sparse.voltage(k * 1e-3), d[k]) << k;
  for (int k = 19999; k >= 0; k -= 1013) ASSERT_EQ(sparse.voltage(k * 1e-3), d[k]) << k;
  bool differs = false;
  for (int k = 0; k < 20000 && !differs; k += 10) differs = other_seed.voltage(k * 1e-3) != d[k];
  EXPECT_TRUE(differs);
}

TEST(Excitation, ValidationNamesTheField) {
  ExcitationSettings s;
  s.v_max = -1;
  EXPECT_NE(error_of(s).find("excitation.v_max"), std::string::npos);
  s = {};
  s.sines = {{0.4, 0.1, 0.0}, {0.4, 0.0, 0.0}};
  EXPECT_NE(error_of(s).find("excitation.sines[1].frequency_hz"), std::string::npos);
  s = {};
  s.steps = {{std::nan(""), 1.0}};
  EXPECT_NE(error_of(s).find("excitation.steps[0].time_s"), std::string::npos);
  s = {};
  s.prbs.order = 1;
  EXPECT_NE(error_of(s).find("excitation.prbs.order"), std::string::npos);
  s.prbs.order = 32;
  EXPECT_NE(error_of(s).find("excitation.prbs.order"), std::string::npos);
  s = {};
  s.prbs.bit_period_s = 0;
  EXPECT_NE(error_of(s).find("excitation.prbs.bit_period_s"), std::string::npos);
  s = {};
  s.prbs.amplitude = -0.1;
  EXPECT_NE(error_of(s).find("excitation.prbs.amplitude_v"), std::string::npos);
  EXPECT_EQ(error_of(paper_excitation()), "");
}

}  // namespace
}  // namespace scp::excitation

// The continuous excitation: the daemon's voltage at every instant, its switches found.
#include <gtest/gtest.h>

#include <cmath>

#include "excitation/excitation.hpp"
#include "tests/benchsim/switching_excitation.hpp"
#include "tools/benchsim/analog_voltage.hpp"

namespace scp::tools::benchsim {
namespace {

TEST(AnalogVoltage, AtItsOwnTimeIsTheDaemonsVoltage) {
  for (const auto& settings : {excitation::paper_excitation(), switching_excitation()}) {
    const excitation::Excitation daemon(settings);
    const AnalogVoltage analog(settings);
    for (int k = 0; k < 200000; ++k) {
      const double t = k * 7.3e-6;
      ASSERT_EQ(analog.at(t, t), daemon.voltage(t)) << t;
    }
  }
}

TEST(AnalogVoltage, LevelTimeHoldsTheSwitchedPartsOnly) {
  const AnalogVoltage analog(switching_excitation());
  const double edge = 0.25;  // a step of −0.3 V (and no PRBS edge: 0.25/0.0123 is not whole)
  const double before = analog.at(edge, edge - 1e-6), after = analog.at(edge, edge);
  EXPECT_NEAR(before - after, 0.3, 1e-12);
  // The sines move with t whatever the level time.
  EXPECT_NE(analog.at(0.2, 0.1), analog.at(0.21, 0.1));
}

TEST(AnalogVoltage, FindsEverySwitch) {
  const AnalogVoltage analog(switching_excitation());
  EXPECT_NEAR(analog.next_switch_after(0.0), 0.0123, 1e-15);
  EXPECT_NEAR(analog.next_switch_after(0.0123), 0.0246, 1e-15);
  EXPECT_NEAR(analog.next_switch_after(0.2499), 0.25, 1e-15);  // the step before the bit at 0.2583
  EXPECT_NEAR(analog.next_switch_after(0.25), 0.0123 * 21, 1e-15);
  EXPECT_TRUE(std::isinf(AnalogVoltage(excitation::paper_excitation()).next_switch_after(5.0)));
}

}  // namespace
}  // namespace scp::tools::benchsim

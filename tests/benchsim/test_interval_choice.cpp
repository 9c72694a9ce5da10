// refine.voltage_interval: estimate on scp-benchsim files (a simulator other than the fit's) with
// a coarse temperature sensor (N3, 0.1 °C), where a one-period shift of the voltage and a sensor
// lag trade against each other in T̄ (refine/voltage_timing.hpp, choose_voltage_interval).
#include <gtest/gtest.h>

#include "refine/fit.hpp"
#include "refine/voltage_timing.hpp"
#include "tests/benchsim/bench_window.hpp"
#include "tools/benchsim/bench_file.hpp"

namespace scp::tools::benchsim {
namespace {

// A continuous voltage read by a thermometer with a 0.5 s lag: the lag is real (tenths of a
// second), so the interval shows only in the second-order term and the daemon's convention
// stands unless `after` earns its place. Seeds 2..4 of scripts/deviations' paper N3 sensor_lag
// cell (seed 2 took `after` before the rule, θ1..θ4 26x off).
TEST(IntervalChoice, ARealSensorLagLeavesAContinuousVoltageBefore) {
  for (const unsigned seed : {2u, 3u, 4u}) {
    BenchFile f = default_bench_file();
    apply_noise_level("N3", f.sim);
    f.sim.deviations.temperature_lag_s = 0.5;
    f.sim.seed = seed;
    refine::FitSettings s;
    s.voltage_hold = estimator::VoltageHold::foh;
    s.voltage_shape = refine::VoltageShape::smooth;
    s.nuisance.sensor_lag.fixed = false;
    EXPECT_EQ(refine::choose_voltage_interval(test::window_of(f), test::theta_of(f), s),
              refine::VoltageInterval::before)
        << "seed " << seed;
  }
}

}  // namespace
}  // namespace scp::tools::benchsim

// The heat a held switch of a continuous drive puts over its interval (hold_voltage_switches,
// mean_square_voltage), against ∫V² of the drive itself (tools/benchsim/analog_voltage.hpp, Gauss–
// Legendre between its own switches): light-stiff's PRBS of 1 s bits rides on a sine that keeps
// moving through every switch.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <vector>

#include "refine/validate_fit.hpp"
#include "refine/voltage_timing.hpp"
#include "tests/benchsim/bench_window.hpp"
#include "tests/benchsim/light_stiff_bench.hpp"
#include "tools/benchsim/analog_voltage.hpp"

namespace scp::tools::benchsim {
namespace {

// ∫ V² over [a, b] where V is smooth (no switch inside): 5-point Gauss–Legendre.
double smooth_square_integral(const AnalogVoltage& v, double a, double b) {
  constexpr std::array<double, 5> nodes = {0.0, 0.5384693101056831, -0.5384693101056831,
                                           0.9061798459386640, -0.9061798459386640};
  constexpr std::array<double, 5> weights = {0.5688888888888889, 0.4786286704993665,
                                             0.4786286704993665, 0.2369268850561891,
                                             0.2369268850561891};
  const double mid = 0.5 * (a + b), half = 0.5 * (b - a);
  double sum = 0.0;
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    const double value = v.at(mid + half * nodes[i], mid);
    sum += weights[i] * value * value;
  }
  return sum * half;
}

// ∫ V² over [a, b], cut at the drive's switches.
double square_integral(const AnalogVoltage& v, double a, double b) {
  double sum = 0.0;
  for (double from = a; from < b;) {
    const double to = std::min(b, v.next_switch_after(from));
    sum += smooth_square_integral(v, from, to);
    from = to;
  }
  return sum;
}

struct HeatError {
  double switches = 0.0;  // Σ |error| over the switches' intervals, V²·s
  double largest = 0.0;   // the largest at one switch
  int count = 0;
};

HeatError switch_heat_error(const std::vector<refine::WindowSample>& w, const AnalogVoltage& v) {
  HeatError e;
  for (std::size_t k = 1; k < w.size(); ++k) {
    if (w[k].voltage_ramp) continue;
    const double error =
        std::abs(refine::mean_square_voltage(w[k - 1], w[k]) * (w[k].t - w[k - 1].t) -
                 square_integral(v, w[k - 1].t, w[k].t));
    e.switches += error;
    e.largest = std::max(e.largest, error);
    ++e.count;
  }
  return e;
}

// Held flat over its interval, the switch from A misses A·V'·Δ² of heat where the sine moves at V';
// going on at the neighbouring chords' slopes it misses O(V''·Δ³). At every one of 60 s's switches
// the error falls by more than 1000×, and the largest is under 1e-10 V²·s (measured 1.3e-12;
// flat: 5.5e-8 at the sine's steepest).
TEST(SwitchHeat, EachSideOfASwitchGoesOnAtItsNeighboursSlope) {
  const BenchFile f = test::light_stiff(60.0);
  const std::vector<refine::WindowSample> rows = test::window_of(f);
  std::vector<refine::WindowSample> storage;
  const auto prepared =
      refine::prepare_window(rows, estimator::VoltageHold::foh, refine::VoltageInterval::before,
                             storage, refine::VoltageShape::smooth, 1.0);
  std::vector<refine::WindowSample> sloped(prepared.begin(), prepared.end());
  std::vector<refine::WindowSample> flat = sloped;
  for (refine::WindowSample& s : flat) s.slope_before = s.slope_after = 0.0;

  const AnalogVoltage voltage(f.excitation, f.clock);
  const HeatError with_slopes = switch_heat_error(sloped, voltage);
  const HeatError held_flat = switch_heat_error(flat, voltage);
  std::printf("%d switches: heat error sum %.3g V2s (flat %.3g), largest %.3g (flat %.3g)\n",
              with_slopes.count, with_slopes.switches, held_flat.switches, with_slopes.largest,
              held_flat.largest);
  ASSERT_GT(with_slopes.count, 20);
  EXPECT_LT(1000.0 * with_slopes.switches, held_flat.switches);
  EXPECT_LT(with_slopes.largest, 1e-10);
}

}  // namespace
}  // namespace scp::tools::benchsim

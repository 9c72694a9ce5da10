#pragma once
// Records whose voltage's timing differs from WindowSample's convention, made by the project's
// plant (drivers/sim, RK4), not by the fit's simulator: a held V logged at the start of the
// interval it drives (the command issued at t), and a continuously varying V logged at each
// sample's instant.

#include <cmath>
#include <functional>
#include <vector>

#include "drivers/sim/plant.hpp"
#include "refine/fit.hpp"

namespace scp::refine::test {

// `seconds` of `plant` at period `dt`: row k holds t_k, the plant's x and T̄ there, and the
// voltage `step(plant, t_k)` returns after advancing the plant over (t_k, t_k + dt] (no
// voltage_since: the row's V is the one logged at its instant).
template <class Step>
std::vector<WindowSample> record_rows(drivers::sim::Plant plant, double seconds, double dt,
                                      Step step) {
  const auto n = static_cast<std::size_t>(std::llround(seconds / dt)) + 1;
  std::vector<WindowSample> w;
  w.reserve(n);
  for (std::size_t k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * dt;
    w.push_back({t, plant.x(), plant.tbar(), 0.0, -1e300});
    w.back().voltage = step(plant, t);
  }
  return w;
}

// The plant holds voltage(t_k) over (t_k, t_{k+1}]; row k logs it (a lab script's log).
inline std::vector<WindowSample> record_logged_after(const drivers::sim::PlantParams& params,
                                                     double seconds, double dt,
                                                     const std::function<double(double)>& voltage) {
  return record_rows(drivers::sim::Plant(params), seconds, dt,
                     [&](drivers::sim::Plant& plant, double t) {
                       const double v = voltage(t);
                       plant.step(v, dt);
                       return v;
                     });
}

// The plant sees V(t) continuously; row k logs V(t_k). `substeps_per_ms`: the plant's RK4.
inline std::vector<WindowSample> record_continuous(const drivers::sim::PlantParams& params,
                                                   double seconds, double dt,
                                                   const std::function<double(double)>& voltage,
                                                   int substeps_per_ms = 20) {
  const auto v_of_t = [&voltage](double t) { return voltage(t); };
  return record_rows(drivers::sim::Plant(params, substeps_per_ms), seconds, dt,
                     [&](drivers::sim::Plant& plant, double t) {
                       const double v = voltage(t);
                       plant.step(drivers::sim::VoltageOfTime(v_of_t), dt);
                       return v;
                     });
}

// A DAC with a first-order hold: V ramps linearly from row k−1's value at t_{k−1} to row k's at
// t_k, rows logging voltage(t_k).
inline std::vector<WindowSample> record_ramped(const drivers::sim::PlantParams& params,
                                               double seconds, double dt,
                                               const std::function<double(double)>& voltage) {
  return record_rows(
      drivers::sim::Plant(params), seconds, dt, [&](drivers::sim::Plant& plant, double t) {
        const double a = voltage(t), b = voltage(t + dt);
        const auto ramp = [a, b, t, dt](double s) { return a + (b - a) * (s - t) / dt; };
        plant.step(drivers::sim::VoltageOfTime(ramp), dt);
        return a;
      });
}

// A smooth voltage that heats and cools the paper's actuator over its thermal time scale and
// moves it at a few tenths of a hertz: slow sines, 0..~3 V.
inline double smooth_voltage(double t) {
  constexpr double kTwoPi = 6.283185307179586;
  return 1.6 + 0.9 * std::sin(kTwoPi * 0.013 * t) + 0.5 * std::sin(kTwoPi * 0.11 * t + 0.4) +
         0.25 * std::sin(kTwoPi * 0.53 * t + 1.1);
}

}  // namespace scp::refine::test

#pragma once
// Recorded windows of an SCP that departs from the fit's model the ways a real bench does
// (issue 28), for the validation tests: a second simulator, independent of both the fit's
// exponential integrator (refine/model_simulator.hpp) and the project's plant (drivers/sim: exact
// thermal step, RK4 mechanics): classical RK4 on the whole state [x, ẋ, T, T_sensor] at 10
// sub-steps per sample, the voltage held over each sample interval as the daemon's DAC holds it
// (window sample k+1 carries the voltage set at sample k, voltage_since = t_k, as record.hpp).
//
// The physics of each deviation, with T the actuator's temperature and all temperatures measured
// from the configured ambient `actuator.ambient_c`:
// - the room is at a(t) = ambient_offset + ambient_drift·t; the heater's power leaves through
//   λ(T̄)·T̄ with T̄ = T − a(t), the rise above the room as it is now;
// - the coil's force follows its temperature above the room at the start, T − ambient_offset
//   (x = 0 where it rests then), so a drifting room moves it, a constant offset does not;
// - R(T̄) = R0(1 + ρ T̄), k(T̄) = k0(1 − κ T̄), λ(T̄) = λ0(1 + γ T̄), on the same temperatures;
// - the thermometer reads T through a first-order lag `sensor_lag`, the displacement sensor reads
//   x + displacement_zero.
// The recorded T̄ is the thermometer's reading above the configured ambient (what the daemon
// records), so an ambient offset or drift appears in it as such.

#include <cmath>
#include <functional>
#include <vector>

#include "drivers/sim/plant_params.hpp"
#include "refine/fit.hpp"

namespace scp::refine::test {

struct Deviations {
  double displacement_zero = 0.0;  // m, added to the x reading
  double ambient_offset = 0.0;     // °C, the room minus the configured ambient
  double ambient_drift = 0.0;      // °C/s, the room's rate of change
  double sensor_lag = 0.0;         // s, the thermometer's time constant
  double resistance_tempco = 0.0;  // ρ, 1/°C
  double stiffness_tempco = 0.0;   // κ, 1/°C (positive: softening)
  double cooling_tempco = 0.0;     // γ, 1/°C
};

namespace detail {

struct DeviationState {
  double x = 0.0, v = 0.0, temp = 0.0, sensor = 0.0;

  DeviationState plus(const DeviationState& d, double h) const {
    return {x + h * d.x, v + h * d.v, temp + h * d.temp, sensor + h * d.sensor};
  }
};

inline DeviationState derivative(const DeviationState& s, double t, double v2,
                                 const drivers::sim::PlantParams& p, const Deviations& d) {
  const double tbar = s.temp - (d.ambient_offset + d.ambient_drift * t);
  const double drive = s.temp - d.ambient_offset;
  const double r = p.R * (1.0 + d.resistance_tempco * tbar);
  const double lambda = p.lambda * (1.0 + d.cooling_tempco * tbar);
  const double k = p.k * (1.0 - d.stiffness_tempco * drive);
  DeviationState out;
  out.x = s.v;
  out.v = (-(p.b + p.alpha1 * drive) * s.v - k * s.x - p.alpha2 * drive) / p.m;
  out.temp = (-lambda * tbar + v2 / r) / p.Cth;
  out.sensor = d.sensor_lag > 0.0 ? (s.temp - s.sensor) / d.sensor_lag : out.temp;
  return out;
}

}  // namespace detail

// `seconds` at period `dt`, noise-free (record.hpp's with_noise adds the sensors' noise).
inline std::vector<WindowSample> deviation_record(const drivers::sim::PlantParams& params,
                                                  double seconds, double dt,
                                                  const std::function<double(double)>& voltage,
                                                  const Deviations& dev) {
  constexpr int kSubsteps = 10;
  const auto n = static_cast<std::size_t>(std::llround(seconds / dt)) + 1;
  std::vector<WindowSample> w;
  w.reserve(n);
  // At rest in the room at t = 0.
  detail::DeviationState s{0.0, 0.0, dev.ambient_offset, dev.ambient_offset};
  double v_prev = 0.0;
  const double h = dt / kSubsteps;
  for (std::size_t k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * dt;
    w.push_back({t, s.x + dev.displacement_zero, s.sensor, v_prev, t - dt});
    v_prev = voltage(t);
    const double v2 = v_prev * v_prev;
    for (int j = 0; j < kSubsteps; ++j) {
      const double tj = t + j * h;
      const auto k1 = detail::derivative(s, tj, v2, params, dev);
      const auto k2 = detail::derivative(s.plus(k1, 0.5 * h), tj + 0.5 * h, v2, params, dev);
      const auto k3 = detail::derivative(s.plus(k2, 0.5 * h), tj + 0.5 * h, v2, params, dev);
      const auto k4 = detail::derivative(s.plus(k3, h), tj + h, v2, params, dev);
      s.x += h / 6.0 * (k1.x + 2.0 * k2.x + 2.0 * k3.x + k4.x);
      s.v += h / 6.0 * (k1.v + 2.0 * k2.v + 2.0 * k3.v + k4.v);
      s.temp += h / 6.0 * (k1.temp + 2.0 * k2.temp + 2.0 * k3.temp + k4.temp);
      s.sensor += h / 6.0 * (k1.sensor + 2.0 * k2.sensor + 2.0 * k3.sensor + k4.sensor);
    }
  }
  return w;
}

}  // namespace scp::refine::test

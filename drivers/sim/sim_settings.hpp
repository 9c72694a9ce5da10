#pragma once
// Settings of the simulated actuator. Plain data: the daemon's config module declares the YAML
// keys and fills this struct; SimDriver's constructor validates it.

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "common/names.hpp"
#include "drivers/sim/plant_params.hpp"

namespace scp::drivers::sim {

// The names SimSettings::step_parameter (sim.step.parameter) takes, each with the member of
// PlantParams it steps (nullptr: none, no step).
inline constexpr NameTable<double PlantParams::*, 9> kStepParameters{{
    {nullptr, "none"},
    {&PlantParams::m, "m"},
    {&PlantParams::R, "R"},
    {&PlantParams::Cth, "Cth"},
    {&PlantParams::lambda, "lambda"},
    {&PlantParams::b, "b"},
    {&PlantParams::k, "k"},
    {&PlantParams::alpha1, "alpha1"},
    {&PlantParams::alpha2, "alpha2"},
}};
// The same names alone, for the configuration's choice list.
inline constexpr auto kStepParameterNames = [] {
  std::array<std::string_view, kStepParameters.size()> names{};
  for (std::size_t i = 0; i < names.size(); ++i) names[i] = kStepParameters[i].name;
  return names;
}();

struct SimSettings {
  PlantParams plant;
  // °C, the configured ambient (actuator.ambient_c): the temperature sensor reads T, absolute, and
  // the daemon subtracts this. The true ambient may differ (deviations.ambient_*).
  double ambient_c = 25.0;
  int substeps = 20;  // RK4 sub-steps per millisecond of simulated time, ≥ 1
  // Gaussian sensor noise, standard deviation in SI units (m, m/s, °C, V); 0 = none.
  double noise_x = 0, noise_xdot = 0, noise_temperature = 0, noise_voltage = 0;
  // s: 0 = white noise; else each channel's noise is a first-order Gauss–Markov process with
  // this correlation time and the standard deviations above (a filtered or drifting sensor).
  double noise_correlation_s = 0;
  std::uint64_t seed = 1;    // of the noise generator; the same seed gives the same samples
  bool measure_xdot = true;  // false: Sample::xdot = NaN (a device without a velocity sensor)
  using Drift = PlantDrift;  // relative drift per hour of each physical parameter
  Drift drift;
  // How the simulated bench departs from the paper's model, each 0 = off (plant_params.hpp): R, k
  // and λ changing with T̄, the true ambient's offset and drift, the temperature sensor's lag.
  PlantDeviations deviations;
  // The displacement sensor's zero, m: it reads x + x_zero (x = 0 is the rest position at the
  // true ambient).
  double x_zero = 0;
  // A heater-current channel, I = V/R(T̄) (Sample::current), with Gaussian noise in A.
  bool measure_current = false;
  double noise_current = 0;
  // A step of one physical parameter (for tests of the health monitor): at loop time at_s the
  // nominal `parameter` (a name of kStepParameters; "none" = no step) is multiplied by `factor`.
  std::string step_parameter = "none";
  double step_at_s = 0.0;
  double step_factor = 1.0;
  // Fault injection (for end-to-end tests of the daemon's safety): from fault_start_s for
  // fault_duration_s (0 = forever) the sensor reports this fault.
  // none | nan_temperature | inf_position | stuck_position | stuck_sensor |
  // temperature_out_of_range | read_error | no_data |
  // stall (see Fault in sim_driver.hpp)
  std::string fault = "none";
  double fault_start_s = 0, fault_duration_s = 0;
  double fault_value_c = 400.0;  // °C reported by temperature_out_of_range
};

// Throws DriverError naming the sim.* key and its allowed range on settings SimDriver cannot
// run (its constructor calls it; a program that only writes a simulated file does too).
void validate(const SimSettings& settings);

}  // namespace scp::drivers::sim

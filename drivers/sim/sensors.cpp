#include "drivers/sim/sensors.hpp"

namespace scp::drivers::sim {

Sensors::Sensors(const SimSettings& settings) noexcept
    : ambient_c_(settings.ambient_c),
      x_zero_(settings.x_zero),
      noise_x_(settings.noise_x),
      noise_xdot_(settings.noise_xdot),
      noise_temperature_(settings.noise_temperature),
      noise_voltage_(settings.noise_voltage),
      noise_current_(settings.noise_current),
      measure_xdot_(settings.measure_xdot),
      measure_current_(settings.measure_current),
      rng_(settings.seed),
      // Any other fixed seed would do; this one (2⁶⁴/φ) differs from `seed` in about half its bits.
      current_rng_(settings.seed ^ 0x9E3779B97F4A7C15ULL) {}

double Sensors::noise(double stddev) noexcept {
  // Drawn only for noisy channels, so enabling one channel does not change another's sequence.
  return stddev > 0.0 ? stddev * normal_(rng_) : 0.0;
}

double Sensors::current_noise() noexcept {
  return noise_current_ > 0.0 ? noise_current_ * current_normal_(current_rng_) : 0.0;
}

double Sensors::read(const Plant& plant, double voltage, double applied, Sample& out) noexcept {
  const double x = x_zero_ != 0.0 ? plant.x() + x_zero_ : plant.x();
  out.x = x + noise(noise_x_);
  const double xdot = plant.xdot() + noise(noise_xdot_);
  out.xdot = measure_xdot_ ? xdot : kNotMeasured;
  out.temperature = plant.sensed_tbar() + ambient_c_ + noise(noise_temperature_);
  out.voltage = voltage + noise(noise_voltage_);
  out.current = measure_current_ ? plant.current(applied) + current_noise() : kNotMeasured;
  return out.current;
}

}  // namespace scp::drivers::sim

#include "drivers/sim/sensors.hpp"

#include <cmath>

namespace scp::drivers::sim {

Sensors::Sensors(const SimSettings& settings) noexcept
    : ambient_c_(settings.ambient_c),
      x_zero_(settings.x_zero),
      noise_x_(settings.noise_x),
      noise_xdot_(settings.noise_xdot),
      noise_temperature_(settings.noise_temperature),
      noise_voltage_(settings.noise_voltage),
      noise_current_(settings.noise_current),
      correlation_s_(settings.noise_correlation_s),
      measure_xdot_(settings.measure_xdot),
      measure_current_(settings.measure_current),
      rng_(settings.seed),
      // Any other fixed seed would do; this one (2⁶⁴/φ) differs from `seed` in about half its bits.
      current_rng_(settings.seed ^ 0x9E3779B97F4A7C15ULL) {}

double Sensors::noise(int channel, double stddev, double t) noexcept {
  // Drawn only for noisy channels, so enabling one channel does not change another's sequence.
  if (!(stddev > 0.0)) return 0.0;
  const double w = normal_(rng_);
  if (!(correlation_s_ > 0.0)) return stddev * w;
  // n ← a·n + √(1 − a²)·σ·w keeps the variance σ² at any interval; the first draw is stationary.
  double& n = coloured_[static_cast<std::size_t>(channel)];
  if (!(t > last_t_)) {
    if (std::isnan(last_t_)) n = stddev * w;
    return n;
  }
  const double a = std::exp(-(t - last_t_) / correlation_s_);
  n = a * n + std::sqrt(-std::expm1(-2.0 * (t - last_t_) / correlation_s_)) * stddev * w;
  return n;
}

double Sensors::current_noise() noexcept {
  return noise_current_ > 0.0 ? noise_current_ * current_normal_(current_rng_) : 0.0;
}

double Sensors::read(const Plant& plant, double voltage, double applied, Sample& out) noexcept {
  const double x = x_zero_ != 0.0 ? plant.x() + x_zero_ : plant.x();
  const double t = plant.time();
  out.x = x + noise(0, noise_x_, t);
  const double xdot = plant.xdot() + noise(1, noise_xdot_, t);
  out.xdot = measure_xdot_ ? xdot : kNotMeasured;
  out.temperature = plant.sensed_tbar() + ambient_c_ + noise(2, noise_temperature_, t);
  out.voltage = voltage + noise(3, noise_voltage_, t);
  last_t_ = t;
  out.current = measure_current_ ? plant.current(applied) + current_noise() : kNotMeasured;
  return out.current;
}

}  // namespace scp::drivers::sim

#pragma once
// What the simulated DAQ reads from the plant, for SimDriver and for scp-benchsim alike: x with
// the sensor's zero, ẋ, the absolute temperature (the configured ambient plus what the sensor
// senses: the true ambient's offset and drift, through its lag), the voltage and, when
// measured, the heater's current, each with its own Gaussian noise.

#include <array>
#include <cstdint>
#include <limits>
#include <random>

#include "drivers/sample.hpp"
#include "drivers/sim/plant.hpp"
#include "drivers/sim/sim_settings.hpp"

namespace scp::drivers::sim {

class Sensors {
 public:
  explicit Sensors(const SimSettings& settings) noexcept;

  // Fills x, ẋ, T, V and the current of `out` (not t) from the plant at its present time.
  // `voltage` is what the row reports as V; `applied` the voltage across the heater just before
  // this instant, which drives the current. Returns the current reading in A, NaN when the
  // channel is off.
  double read(const Plant& plant, double voltage, double applied, Sample& out) noexcept;

 private:
  // The next noise value of `channel` (x, ẋ, T, V) at the plant's time `t`.
  double noise(int channel, double stddev, double t) noexcept;
  double current_noise() noexcept;

  double ambient_c_;
  double x_zero_;
  double noise_x_, noise_xdot_, noise_temperature_, noise_voltage_, noise_current_;
  double correlation_s_;
  // The coloured noise's state per channel and when it was last drawn (NaN: not yet).
  std::array<double, 4> coloured_{};
  double last_t_ = std::numeric_limits<double>::quiet_NaN();
  bool measure_xdot_;
  bool measure_current_;
  // x, ẋ, T and V draw from one generator in that order (as before the current channel
  // existed); the current from a second, so that measuring it leaves the others' noise unchanged.
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
  std::mt19937_64 current_rng_;
  std::normal_distribution<double> current_normal_{0.0, 1.0};
};

}  // namespace scp::drivers::sim

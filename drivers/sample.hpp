#pragma once
// One reading of the actuator as a driver delivers it, in SI units.

#include <limits>

namespace scp::drivers {

inline constexpr double kNotMeasured = std::numeric_limits<double>::quiet_NaN();

struct Sample {
  double t = 0.0;                     // s, on the loop's clock (seconds since the loop started)
  double x = kNotMeasured;            // m, length change of the actuator
  double xdot = kNotMeasured;         // m/s; NaN when the device does not measure it
  double temperature = kNotMeasured;  // °C, absolute (the estimator subtracts the ambient)
  // V, the voltage applied over the interval that ends at t (read back, or the last command when
  // the device cannot read it back). A DAC holds its output between commands, so this is the value
  // the estimator treats as constant over that interval.
  double voltage = kNotMeasured;
};

}  // namespace scp::drivers

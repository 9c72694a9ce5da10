#pragma once
// One reading of the actuator as a driver delivers it, in SI units.

#include <limits>

namespace scp::drivers {

inline constexpr double kNotMeasured = std::numeric_limits<double>::quiet_NaN();

struct Sample {
  // s, on the loop's clock (seconds since the loop started): when x, ẋ and T were sampled. The
  // cycle's deadline unless the driver knows better (a transaction's time stamp on a real link).
  double t = 0.0;
  double x = kNotMeasured;            // m, length change of the actuator
  double xdot = kNotMeasured;         // m/s; NaN when the device does not measure it
  double temperature = kNotMeasured;  // °C, absolute (the estimator subtracts the ambient)
  // V, the voltage applied over the interval that ends at t (read back, or the last command when
  // the device cannot read it back). A DAC holds its output between commands, so this is the value
  // the estimator treats as constant over that interval.
  double voltage = kNotMeasured;
  // s, loop clock: when `voltage` took effect at the actuator, if that was after the previous
  // sample (a command whose write landed mid-cycle, docs/numerics.md "Time on a real link");
  // before that instant the previous sample's voltage was applied. −∞ (the default): the voltage
  // was applied over the whole interval, as a DAC switching at sample instants does.
  double voltage_since = -std::numeric_limits<double>::infinity();
  // A, the heater's current at t, driven by `voltage` (the DAQ's measurement); NaN when the device
  // does not measure it. Measured, the refinement's thermal input is the power V·I.
  double current = kNotMeasured;
};

}  // namespace scp::drivers

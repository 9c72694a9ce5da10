#pragma once
// A simulated SCP actuator behind the driver contract: the plant advances with the loop's clock
// (CycleTime::t), so batch runs and real-time runs see the same physics.

#include <array>
#include <cmath>
#include <cstdint>
#include <string_view>

#include "drivers/driver.hpp"
#include "drivers/sim/plant.hpp"
#include "drivers/sim/sensors.hpp"
#include "drivers/sim/sim_settings.hpp"

namespace scp::drivers::sim {

enum class Fault : std::uint8_t {
  none,
  nan_temperature,           // temperature reads NaN
  inf_position,              // x reads +infinity (an overflowing converter)
  stuck_position,            // x frozen at its last value before the fault
  stuck_sensor,              // x, ẋ and T all frozen at their last values (a dead DAQ repeating)
  temperature_out_of_range,  // temperature reads fault_value_c
  read_error,                // read() fails with "simulated sensor read error"
  no_data,                   // read() returns IoStatus::no_data
  // The first read() in the window blocks for fault_duration_s of wall-clock time (0: forever,
  // until the process is killed), like a hung device call; for tests of the service watchdog.
  // Only the simulated time is the loop's; this one fault deliberately spends real time.
  stall,
};

// Parses a SimSettings::fault name; throws DriverError listing the allowed names.
Fault parse_fault(std::string_view name);
// The member of PlantParams a SimSettings::step_parameter name steps (nullptr for "none");
// throws DriverError naming sim.step.parameter and listing the allowed names.
double PlantParams::*parse_step_parameter(std::string_view name);

class SimDriver final : public Driver {
 public:
  // Throws DriverError naming the field ("sim.substeps must be ≥ 1 ...") on invalid settings.
  explicit SimDriver(const SimSettings& settings);

  std::string_view name() const noexcept override { return "sim"; }
  void open() override;
  // Advances the plant from its current time to now.t with the voltage last written held, then
  // samples it. A non-finite now.t fails; a now.t at or before the plant's time does not advance.
  IoResult read(const CycleTime& now, Sample& out) noexcept override;
  // Advances the physics alone to loop time t (no sample, no noise drawn): a wall-clock peer
  // (scp-simdaq --wallclock) brings the plant to the instant a new command lands.
  void advance_to(double t) noexcept {
    if (std::isfinite(t) && t > plant_.time()) plant_.step(command_, t - plant_.time());
  }
  // Stores the command for the next interval; a non-finite value is refused and 0 V held.
  IoResult write_voltage(double volts) noexcept override;
  void safe_state() noexcept override;
  void close() noexcept override;
  DriverStats stats() const noexcept override { return stats_; }
  bool true_theta(double t, std::array<double, 6>& theta) const noexcept override;

  const Plant& plant() const noexcept { return plant_; }
  double command() const noexcept { return command_; }
  // The heater current read with the latest sample (A, Sample::current), NaN when
  // settings().measure_current is false.
  double current() const noexcept { return current_; }

 private:
  bool fault_active(double t) const noexcept;
  // Advances the plant to t, applying SimSettings::step on the way.
  void advance_plant(double t) noexcept;
  void stall() noexcept;

  SimSettings settings_;
  Fault fault_;
  double PlantParams::*step_field_;  // SimSettings::step_parameter; nullptr: no step
  Plant plant_;
  Sensors sensors_;
  double command_ = 0.0;  // V held from the last read onward
  double current_ = kNotMeasured;
  bool stalled_ = false;       // stall happens once per window
  bool step_done_ = false;     // SimSettings::step applied
  bool have_stuck_x_ = false;  // stuck_position: x reported before the fault began
  double stuck_x_ = 0.0;
  double last_x_ = 0.0;
  bool have_stuck_sample_ = false;  // stuck_sensor: the reading before the fault began
  Sample stuck_sample_{};
  Sample last_sample_{};
  DriverStats stats_;
};

}  // namespace scp::drivers::sim

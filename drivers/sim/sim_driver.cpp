#include "drivers/sim/sim_driver.hpp"

#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <string>
#include <thread>
#include <utility>

#include "common/checks.hpp"

namespace scp::drivers::sim {

namespace {

void require(bool ok, const std::string& field, const std::string& rule, double got,
             const std::string& remedy) {
  checks::require<DriverError>(ok, field, rule, got, remedy);
}

void require_positive(double v, const char* field, const char* table_value) {
  require(std::isfinite(v) && v > 0.0, field, "a finite number > 0", v,
          std::string("Table I uses ") + table_value);
}

void require_non_negative(double v, const std::string& field, const std::string& remedy) {
  require(std::isfinite(v) && v >= 0.0, field, "a finite number >= 0", v, remedy);
}

// The deviations of a real bench (issue 28). The bounds keep the model physical and the
// integration stable: a lag of at least 1 ms against RK4 sub-steps of at most 1 ms.
void validate_bench(const SimSettings& s) {
  const PlantDeviations& d = s.deviations;
  for (const auto& [v, field] : {std::pair{d.resistance_tempco, "sim.tempco.R"},
                                 std::pair{d.stiffness_softening, "sim.tempco.k_softening"},
                                 std::pair{d.cooling_tempco, "sim.tempco.lambda"}}) {
    require(std::isfinite(v) && std::abs(v) <= 0.02, field, "a number in [-0.02, 0.02] per degC", v,
            "use 0 for the paper's model; a nickel heater's R has 0.0059");
  }
  require(std::isfinite(d.ambient_offset_c) && std::abs(d.ambient_offset_c) <= 50.0,
          "sim.ambient.offset_c", "a number in [-50, 50] degC", d.ambient_offset_c,
          "the true ambient less actuator.ambient_c; 0 when they agree");
  require(std::isfinite(d.ambient_drift_c_per_h) && std::abs(d.ambient_drift_c_per_h) <= 100.0,
          "sim.ambient.drift_c_per_h", "a number in [-100, 100] degC/h", d.ambient_drift_c_per_h,
          "e.g. 1 for a room warming by 1 degC per hour");
  const double lag = d.temperature_lag_s;
  require(lag == 0.0 || (lag >= 1e-3 && lag <= 100.0), "sim.sensor.temperature_lag_s",
          "0 or a number in [0.001, 100] s", lag, "a fine thermocouple lags by 0.1-0.5 s");
  require(std::isfinite(s.x_zero) && std::abs(s.x_zero) <= 1.0, "sim.sensor.x_zero_m",
          "a number in [-1, 1] m", s.x_zero, "what the displacement sensor reads at rest");
  require_non_negative(s.noise_current, "sim.noise.current", "use 0 for a noise-free sensor");
}

}  // namespace

void validate(const SimSettings& s) {
  const PlantParams& p = s.plant;
  require_positive(p.m, "sim.plant.m", "0.1 kg");
  require_positive(p.R, "sim.plant.R", "1 ohm");
  require_positive(p.Cth, "sim.plant.Cth", "0.9090 Ws/degC");
  require_positive(p.lambda, "sim.plant.lambda", "0.0540 W/degC");
  require_positive(p.k, "sim.plant.k", "181.3 N/m");
  // b = 0 or alpha1 = 0 still give a damped, stable plant; negative values would not.
  require_non_negative(p.b, "sim.plant.b", "Table I uses 124.7 Ns/m");
  require_non_negative(p.alpha1, "sim.plant.alpha1", "Table I uses 0.08 Ns/(m degC)");
  // A negative alpha2 is an actuator that lengthens when heated: unusual but physical.
  require(std::isfinite(p.alpha2), "sim.plant.alpha2", "a finite number", p.alpha2,
          "Table I uses 0.01 N/degC");
  require(std::isfinite(s.ambient_c) && s.ambient_c > -273.15, "actuator.ambient_c",
          "a finite temperature above -273.15 degC", s.ambient_c, "e.g. 25");
  require(s.substeps >= 1 && s.substeps <= 100000, "sim.substeps", "an integer in [1, 100000]",
          s.substeps, "20 sub-steps per ms keep RK4 accurate to ~1e-9 on the fast pole");
  const char* noise_remedy = "use 0 for a noise-free sensor";
  require_non_negative(s.noise_x, "sim.noise.x", noise_remedy);
  require_non_negative(s.noise_xdot, "sim.noise.xdot", noise_remedy);
  require_non_negative(s.noise_temperature, "sim.noise.temperature", noise_remedy);
  require_non_negative(s.noise_voltage, "sim.noise.voltage", noise_remedy);
  require_non_negative(s.noise_correlation_s, "sim.noise.correlation_s",
                       "use 0 for white noise, else the sensor's correlation time in s");
  const SimSettings::Drift& d = s.drift;
  const char* drift_remedy = "give a relative rate per hour, e.g. 0.01 for +1 %/h";
  for (const auto& [v, field] :
       {std::pair{d.m, "sim.drift.m"}, std::pair{d.R, "sim.drift.R"},
        std::pair{d.Cth, "sim.drift.Cth"}, std::pair{d.lambda, "sim.drift.lambda"},
        std::pair{d.b, "sim.drift.b"}, std::pair{d.k, "sim.drift.k"},
        std::pair{d.alpha1, "sim.drift.alpha1"}, std::pair{d.alpha2, "sim.drift.alpha2"}}) {
    require(std::isfinite(v), field, "a finite number", v, drift_remedy);
  }
  validate_bench(s);
  require_non_negative(s.step_at_s, "sim.step.at_s", "seconds after the loop starts");
  require(std::isfinite(s.step_factor) && s.step_factor > 0.0, "sim.step.factor",
          "a positive number", s.step_factor, "e.g. 1.1 for +10 %");
  require_non_negative(s.fault_start_s, "sim.fault.start_s", "seconds after the loop starts");
  require_non_negative(s.fault_duration_s, "sim.fault.duration_s", "use 0 for a fault that lasts");
  require(std::isfinite(s.fault_value_c), "sim.fault.value_c", "a finite temperature",
          s.fault_value_c, "e.g. 400 (above the safety limit)");
  parse_fault(s.fault);
  parse_step_parameter(s.step_parameter);
}

Fault parse_fault(std::string_view name) {
  if (name == "none") return Fault::none;
  if (name == "nan_temperature") return Fault::nan_temperature;
  if (name == "inf_position") return Fault::inf_position;
  if (name == "stuck_position") return Fault::stuck_position;
  if (name == "stuck_sensor") return Fault::stuck_sensor;
  if (name == "temperature_out_of_range") return Fault::temperature_out_of_range;
  if (name == "read_error") return Fault::read_error;
  if (name == "no_data") return Fault::no_data;
  if (name == "stall") return Fault::stall;
  throw DriverError("sim.fault.kind: unknown fault '" + std::string(name) +
                    "'; use one of none, nan_temperature, inf_position, stuck_position, "
                    "stuck_sensor, temperature_out_of_range, read_error, no_data, stall");
}

double PlantParams::*parse_step_parameter(std::string_view name) {
  if (const auto field = value_of(kStepParameters, name)) return *field;
  std::string names;
  for (const auto& entry : kStepParameters)
    names += (names.empty() ? "" : ", ") + std::string(entry.name);
  throw DriverError("sim.step.parameter: unknown parameter '" + std::string(name) +
                    "'; use one of " + names);
}

SimDriver::SimDriver(const SimSettings& settings)
    : settings_((validate(settings), settings)),
      fault_(parse_fault(settings.fault)),
      step_field_(parse_step_parameter(settings.step_parameter)),
      plant_(settings.plant, settings.substeps, settings.drift, settings.deviations),
      sensors_(settings) {}

void SimDriver::open() {
  command_ = 0.0;
  stats_.link_up = true;
}

bool SimDriver::fault_active(double t) const noexcept {
  if (fault_ == Fault::none || t < settings_.fault_start_s) return false;
  return settings_.fault_duration_s <= 0.0 ||
         t < settings_.fault_start_s + settings_.fault_duration_s;
}

void SimDriver::advance_plant(double t) noexcept {
  const SimSettings& s = settings_;
  if (!step_done_ && step_field_ != nullptr && t >= s.step_at_s) {
    if (s.step_at_s > plant_.time()) plant_.step(command_, s.step_at_s - plant_.time());
    PlantParams p = plant_.nominal_params();
    p.*step_field_ *= s.step_factor;
    plant_.set_params(p);
    step_done_ = true;
  }
  if (t > plant_.time()) plant_.step(command_, t - plant_.time());
}

IoResult SimDriver::read(const CycleTime& now, Sample& out) noexcept {
  ++stats_.reads;
  if (!std::isfinite(now.t)) {
    ++stats_.read_errors;
    return IoResult::fail("sim: non-finite cycle time");
  }
  // The physics moves on whatever the sensor does: a faulty sensor does not stop time.
  advance_plant(now.t);

  const bool faulty = fault_active(now.t);
  if (faulty && fault_ == Fault::stall && !stalled_) {
    stalled_ = true;
    stall();
  }
  if (faulty && fault_ == Fault::read_error) {
    ++stats_.read_errors;
    return IoResult::fail("simulated sensor read error");
  }
  if (faulty && fault_ == Fault::no_data) return {IoStatus::no_data, "simulated: no new data"};

  out.t = now.t;
  current_ = sensors_.read(plant_, command_, command_, out);

  if (faulty && fault_ == Fault::nan_temperature) out.temperature = kNotMeasured;
  if (faulty && fault_ == Fault::temperature_out_of_range) {
    out.temperature = settings_.fault_value_c;
  }
  if (faulty && fault_ == Fault::stuck_position) {
    if (!have_stuck_x_) {
      stuck_x_ = stats_.reads > 1 ? last_x_ : out.x;
      have_stuck_x_ = true;
    }
    out.x = stuck_x_;
  } else {
    have_stuck_x_ = false;
  }
  last_x_ = out.x;
  if (faulty && fault_ == Fault::inf_position) out.x = std::numeric_limits<double>::infinity();
  if (faulty && fault_ == Fault::stuck_sensor) {
    if (!have_stuck_sample_) {
      stuck_sample_ = stats_.reads > 1 ? last_sample_ : out;
      have_stuck_sample_ = true;
    }
    out.x = stuck_sample_.x;
    out.xdot = stuck_sample_.xdot;
    out.temperature = stuck_sample_.temperature;
  } else {
    have_stuck_sample_ = false;
  }
  last_sample_ = out;
  return IoResult::ok();
}

void SimDriver::stall() noexcept {
  // A hung device call, to exercise the service watchdog: wall-clock time, on purpose.
  const double seconds = settings_.fault_duration_s;
  do {
    std::this_thread::sleep_for(std::chrono::duration<double>(seconds > 0.0 ? seconds : 3600.0));
  } while (seconds <= 0.0);
}

IoResult SimDriver::write_voltage(double volts) noexcept {
  ++stats_.writes;
  if (!std::isfinite(volts)) {
    ++stats_.write_errors;
    command_ = 0.0;
    stats_.output_v = 0.0;
    return IoResult::fail("sim: non-finite voltage command refused, holding 0 V");
  }
  command_ = volts;
  stats_.output_v = volts;
  return IoResult::ok();
}

void SimDriver::safe_state() noexcept {
  command_ = 0.0;
  stats_.output_v = 0.0;
}

void SimDriver::close() noexcept {
  command_ = 0.0;
}

bool SimDriver::true_theta(double t, std::array<double, 6>& theta) const noexcept {
  if (!std::isfinite(t)) return false;
  theta = theta_of(drifted(plant_.nominal_params(), plant_.drift(), t));
  return true;
}

}  // namespace scp::drivers::sim

#include "tools/benchsim/bench_file.hpp"

#include <charconv>
#include <cmath>
#include <ostream>
#include <stdexcept>
#include <string>

#include "drivers/sim/plant.hpp"
#include "drivers/sim/sensors.hpp"
#include "drivers/sim/sim_driver.hpp"
#include "excitation/excitation.hpp"
#include "tools/benchsim/analog_voltage.hpp"

namespace scp::tools::benchsim {

namespace {

using drivers::sim::Plant;
using drivers::sim::VoltageOfTime;

// The shortest text that reads back as the same double (as the daemon's recorder writes).
void append(std::string& line, double value) {
  char buf[32];
  const auto end = std::to_chars(buf, buf + sizeof buf, value).ptr;
  line.append(buf, end);
}

std::string text(double value) {
  std::string s;
  append(s, value);
  return s;
}

void require(bool ok, const std::string& message) {
  if (!ok) throw std::invalid_argument(message);
}

// Rows in the file; throws on settings the run cannot use (SimDriver's checks name sim.* keys).
long long validate(const BenchFile& f) {
  require(std::isfinite(f.period_s) && f.period_s >= 1e-6 && f.period_s <= 10.0,
          "the period must be in [1e-6, 10] s (got " + text(f.period_s) + ")");
  require(std::isfinite(f.duration_s) && f.duration_s > 0.0,
          "the duration must be a number of seconds > 0 (got " + text(f.duration_s) + ")");
  const double intervals = std::round(f.duration_s / f.period_s);
  require(intervals >= 1.0 && intervals <= 1e9,
          "the duration must span 1 to 1e9 periods (got " + text(intervals) + ")");
  require(f.sim.fault == "none", "a bench file has no injected fault (sim.fault " + f.sim.fault +
                                     "); use SimDriver for fault tests");
  drivers::sim::validate(f.sim);  // throws DriverError naming the sim.* key
  return static_cast<long long>(intervals) + 1;
}

void describe(const BenchFile& f, std::ostream& out) {
  const auto& p = f.sim.plant;
  const auto& d = f.sim.deviations;
  const auto theta = drivers::sim::theta_of(p);
  out << "# scp-benchsim: a simulated SCP bench, not a recording (tools/benchsim)\n"
      << "# plant at Tbar = 0 from the true ambient: m " << text(p.m) << " kg, R " << text(p.R)
      << " ohm, Cth " << text(p.Cth) << " Ws/degC, lambda " << text(p.lambda) << " W/degC, b "
      << text(p.b) << " Ns/m, k " << text(p.k) << " N/m, alpha1 " << text(p.alpha1)
      << " Ns/(m degC), alpha2 " << text(p.alpha2) << " N/degC\n# theta";
  for (const double th : theta) out << ' ' << text(th);
  out << "\n# deviations: R tempco " << text(d.resistance_tempco) << " /degC, k softening "
      << text(d.stiffness_softening) << " /degC, lambda tempco " << text(d.cooling_tempco)
      << " /degC, true ambient offset " << text(d.ambient_offset_c) << " degC and drift "
      << text(d.ambient_drift_c_per_h) << " degC/h, T sensor lag " << text(d.temperature_lag_s)
      << " s, x sensor zero " << text(f.sim.x_zero) << " m\n"
      << "# sensors: T absolute (configured ambient " << text(f.sim.ambient_c)
      << " degC); noise sd x " << text(f.sim.noise_x) << " m, xdot " << text(f.sim.noise_xdot)
      << " m/s" << (f.sim.measure_xdot ? "" : " (not measured: blank)") << ", T "
      << text(f.sim.noise_temperature) << " degC, V " << text(f.sim.noise_voltage) << " V, I "
      << text(f.sim.noise_current) << " A" << (f.sim.measure_current ? "" : " (no I column)")
      << "; seed " << f.sim.seed << "\n# voltage: " << name_of(f.timing)
      << (f.excite ? "" : " (excitation off: 0 V)") << "; integrator: RK4 on x, xdot, Tbar"
      << (d.temperature_lag_s > 0 ? " and the T sensor" : "") << " together, " << f.sim.substeps
      << " sub-steps per ms, cut at every switch of V\n";
  if (f.clock.rate_error != 0.0 || f.clock.offset_s != 0.0) {
    out << "# the voltage source's clock: rate error " << text(f.clock.rate_error * 1e6)
        << " ppm against the DAQ's, offset " << text(f.clock.offset_s) << " s\n";
  }
}

// Advances `plant` over one period and returns the voltage applied just before its end.
class Stepper {
 public:
  Stepper(const BenchFile& f, const AnalogVoltage& v) : timing_(f.timing), v_(v) {}

  double command(double t) const noexcept { return v_.at(t, t); }

  double advance(Plant& plant, double from, double to) const noexcept {
    if (timing_ != VoltageTiming::continuous) {
      const double held = command(from);
      const auto dac = [held](double /*t*/) noexcept { return held; };
      plant.set_time(from);
      plant.step(VoltageOfTime(dac), to - from);
      return held;
    }
    // A switch within this tolerance of a row's t is taken at the row's t: t = k·period and a
    // bit edge n·bit_period computed apart may differ by rounding.
    const double tolerance = 1e-9 * (to - from);
    double start = from, level_time = from;
    while (start < to) {
      const double edge = v_.next_switch_after(start + tolerance);
      const double end = edge < to - tolerance ? edge : to;
      level_time = 0.5 * (start + end);
      const auto analog = [this, level_time](double t) noexcept { return v_.at(t, level_time); };
      plant.set_time(start);
      plant.step(VoltageOfTime(analog), end - start);
      start = end;
    }
    return v_.at(to, level_time);
  }

 private:
  VoltageTiming timing_;
  const AnalogVoltage& v_;
};

excitation::ExcitationSettings zero_volts() {
  excitation::ExcitationSettings s;
  s.v_max = 0.0;
  return s;
}

void append_row(std::string& line, const drivers::Sample& s, bool since_column, double current,
                bool current_column) {
  line.clear();
  append(line, s.t);
  line += ',';
  append(line, s.x);
  line += ',';
  if (std::isfinite(s.xdot)) append(line, s.xdot);
  line += ',';
  append(line, s.temperature);
  line += ',';
  append(line, s.voltage);
  if (since_column) line += ',';  // blank: V was applied over the whole interval
  if (current_column) {
    line += ',';
    append(line, current);
  }
  line += '\n';
}

}  // namespace

VoltageTiming parse_voltage_timing(std::string_view name) {
  if (name == "continuous") return VoltageTiming::continuous;
  if (name == "dac-before") return VoltageTiming::dac_before;
  if (name == "dac-after") return VoltageTiming::dac_after;
  throw std::invalid_argument("unknown voltage timing '" + std::string(name) +
                              "'; use continuous, dac-before or dac-after");
}

std::string_view name_of(VoltageTiming timing) noexcept {
  switch (timing) {
    case VoltageTiming::continuous:
      return "continuous (each row's V is V(t) at its t; replay with voltage_hold: foh)";
    case VoltageTiming::dac_before:
      return "dac-before (held by a DAC; each row's V was applied over the interval before it)";
    case VoltageTiming::dac_after:
      return "dac-after (held by a DAC; each row's V is the command issued at its t)";
  }
  return "";
}

void apply_noise_level(std::string_view level, drivers::sim::SimSettings& sim) {
  struct Level {
    std::string_view name;
    double x, xdot, temperature;
    bool measure_xdot;
  };
  // scripts/montecarlo's NOISE table.
  static constexpr Level kLevels[] = {{"N0", 0.0, 0.0, 0.0, true},
                                      {"N1", 1e-7, 1e-6, 1e-3, true},
                                      {"N2", 1e-6, 1e-5, 1e-2, true},
                                      {"N3", 1e-6, 0.0, 0.1, false}};
  for (const Level& l : kLevels) {
    if (l.name != level) continue;
    sim.noise_x = l.x;
    sim.noise_xdot = l.xdot;
    sim.noise_temperature = l.temperature;
    sim.measure_xdot = l.measure_xdot;
    return;
  }
  throw std::invalid_argument("unknown noise level '" + std::string(level) +
                              "'; use N0, N1, N2 or N3 (scripts/montecarlo's levels)");
}

BenchFile default_bench_file() {
  BenchFile f;
  f.excitation = excitation::paper_excitation();
  return f;
}

void write_bench_file(const BenchFile& f, std::ostream& out) {
  const long long rows = validate(f);
  const AnalogVoltage voltage(f.excite ? f.excitation : zero_volts(), f.clock);
  const Stepper stepper(f, voltage);
  Plant plant(f.sim.plant, f.sim.substeps, f.sim.drift, f.sim.deviations);
  drivers::sim::Sensors sensors(f.sim);
  const bool since_column = f.timing == VoltageTiming::dac_before;

  describe(f, out);
  out << "t,x,xdot,T,V" << (since_column ? ",V_since" : "") << (f.sim.measure_current ? ",I" : "")
      << '\n';
  std::string line;
  double previous_command = 0.0;  // before t = 0 the actuator was at rest, at 0 V
  for (long long k = 0; k < rows; ++k) {
    const double t = static_cast<double>(k) * f.period_s;
    double applied = 0.0;  // just before t
    if (k > 0) applied = stepper.advance(plant, static_cast<double>(k - 1) * f.period_s, t);
    const double command = stepper.command(t);
    double logged = command;
    if (f.timing == VoltageTiming::dac_before) logged = previous_command;
    if (f.timing == VoltageTiming::continuous && k == 0) applied = command;
    drivers::Sample s;
    s.t = t;
    const double current = sensors.read(plant, logged, applied, s);
    append_row(line, s, since_column, current, f.sim.measure_current);
    out.write(line.data(), static_cast<std::streamsize>(line.size()));
    previous_command = command;
  }
  out.flush();
  if (!out) throw std::runtime_error("writing the file failed (disk full?)");
}

}  // namespace scp::tools::benchsim

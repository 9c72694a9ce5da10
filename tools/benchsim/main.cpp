// scp-benchsim: writes a replay file of a simulated SCP bench that departs from the paper's model
// the ways a real one does, integrated unlike the fit (tools/benchsim/bench_file.hpp).
//
//   scp-benchsim --out bench.csv --voltage dac-after --noise N1 --seed 3 --temperature-lag 0.3

#include <CLI/CLI.hpp>
#include <array>
#include <cstdio>
#include <exception>
#include <fstream>
#include <string>
#include <utility>

#include "daemon/config/daemon_config.hpp"
#include "drivers/driver.hpp"
#include "tools/benchsim/bench_file.hpp"

namespace {

using scp::tools::benchsim::BenchFile;

struct Options {
  std::string out, config, voltage = "continuous", noise = "N0";
  double generator_ppm = 0.0;
  double noise_x = -1, noise_xdot = -1, noise_temperature = -1;
  bool no_xdot = false;
};

// The deviation flags and the sim.* key each sets. Their ranges are the sim's own
// (drivers::sim::validate): its error names the key, and the message adds the flag.
constexpr std::array<std::pair<const char*, const char*>, 7> kDeviationFlags{{
    {"--resistance-tempco", "sim.tempco.R"},
    {"--stiffness-softening", "sim.tempco.k_softening"},
    {"--cooling-tempco", "sim.tempco.lambda"},
    {"--ambient-offset", "sim.ambient.offset_c"},
    {"--ambient-drift", "sim.ambient.drift_c_per_h"},
    {"--temperature-lag", "sim.sensor.temperature_lag_s"},
    {"--x-zero", "sim.sensor.x_zero_m"},
}};

void add_deviation_options(CLI::App& app, BenchFile& f) {
  auto& d = f.sim.deviations;
  app.add_option("--resistance-tempco", d.resistance_tempco,
                 "rho in R = R0(1 + rho Tbar), 1/degC (nickel 0.0059; default 0)");
  app.add_option("--stiffness-softening", d.stiffness_softening,
                 "kappa in k = k0(1 - kappa Tbar), 1/degC (default 0)");
  app.add_option("--cooling-tempco", d.cooling_tempco,
                 "gamma in lambda = lambda0(1 + gamma Tbar), 1/degC (default 0)");
  app.add_option("--ambient-offset", d.ambient_offset_c,
                 "true ambient minus the configured one, degC (default 0)");
  app.add_option("--ambient-drift", d.ambient_drift_c_per_h,
                 "drift of the true ambient, degC per hour (default 0)");
  app.add_option("--temperature-lag", d.temperature_lag_s,
                 "first-order lag of the T sensor, s: 0 (default) or 0.001 to 100");
  app.add_option("--x-zero", f.sim.x_zero, "what the x sensor reads at rest, m (default 0)");
}

// The sim's message, led by the flag that set the key it names.
std::string with_flag(const std::string& message) {
  for (const auto& [flag, key] : kDeviationFlags) {
    if (message.find(key) != std::string::npos) return std::string(flag) + ": " + message;
  }
  return message;
}

void add_sensor_options(CLI::App& app, BenchFile& f, Options& o) {
  app.add_option("--noise", o.noise,
                 "sensor noise level of scripts/montecarlo: N0 none (default); N1 x 1e-7 m, "
                 "xdot 1e-6 m/s, T 1e-3 degC; N2 x 1e-6, xdot 1e-5, T 1e-2; N3 x 1e-6, no xdot, "
                 "T 0.1")
      ->check(CLI::IsMember({"N0", "N1", "N2", "N3"}));
  app.add_option("--noise-x", o.noise_x, "sd on x, m (overrides --noise)")
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--noise-xdot", o.noise_xdot, "sd on xdot, m/s (overrides --noise)")
      ->check(CLI::Range(0.0, 10.0));
  app.add_option("--noise-temperature", o.noise_temperature, "sd on T, degC (overrides --noise)")
      ->check(CLI::Range(0.0, 100.0));
  app.add_option("--noise-voltage", f.sim.noise_voltage, "sd on the V column, V (default 0)")
      ->check(CLI::Range(0.0, 10.0));
  app.add_flag("--no-xdot", o.no_xdot, "leave xdot blank (no velocity sensor; N3 implies it)");
  app.add_flag("--current", f.sim.measure_current,
               "add an I column: the heater current V/R(Tbar) at each row's t, A");
  app.add_option("--noise-current", f.sim.noise_current, "sd on I, A (default 0)")
      ->check(CLI::Range(0.0, 10.0));
  app.add_option("--seed", f.sim.seed, "seed of the noise (default 1)");
}

void apply_config(const std::string& path, BenchFile& f) {
  const scp::config::DaemonConfig cfg = scp::config::load_config_file(path);
  const scp::drivers::sim::SimSettings& sim = cfg.driver.sim;
  f.sim.plant = sim.plant;
  f.sim.drift = sim.drift;
  f.sim.ambient_c = sim.ambient_c;
  f.excitation = cfg.excitation.settings;
  f.excite = cfg.excitation.enabled;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "scp-benchsim: writes a replay CSV (t,x,xdot,T,V[,V_since][,I]) of a simulated SCP bench "
      "that can be wrong the ways a real one is, integrated unlike the refinement (RK4 on all "
      "states, 20 sub-steps per ms, the voltage continuous or held by a DAC). Replay it with "
      "scp-estimatord --offline --replay FILE. Test data; not installed."};
  BenchFile f = scp::tools::benchsim::default_bench_file();
  Options o;
  app.add_option("--out", o.out, "the CSV file to write")->required();
  app.add_option("--config", o.config,
                 "take the plant (driver.sim.plant, drift), actuator.ambient_c and the excitation "
                 "from a daemon config, e.g. config/actuators/light-stiff.yaml (default: Table I, "
                 "25 degC, the paper's four sines); its noise, seed and period are not used");
  app.add_option("--duration", f.duration_s, "s of data (default 300)")
      ->check(CLI::Range(1e-6, 1e7));
  app.add_option("--period", f.period_s, "s between rows (default 0.001)")
      ->check(CLI::Range(1e-6, 10.0));
  app.add_option("--voltage", o.voltage,
                 "continuous (default): V(t) analytic, each row's V its value at t (replay with "
                 "estimator.voltage_hold: foh); dac-before: held over each period, each row's V "
                 "applied over the interval before it (the daemon's convention; V_since column); "
                 "dac-after: held, each row's V the command issued at its t")
      ->check(CLI::IsMember({"continuous", "dac-before", "dac-after"}));
  app.add_option("--substeps", f.sim.substeps, "RK4 sub-steps per ms (default 20)")
      ->check(CLI::Range(1, 100000));
  app.add_option("--generator-clock-ppm", o.generator_ppm,
                 "the voltage source's clock rate error against the DAQ's, ppm: its steps and "
                 "bits then switch at every place between two rows in turn (default 0: on rows)")
      ->check(CLI::Range(-1000.0, 1000.0));
  app.add_option("--generator-clock-offset", f.clock.offset_s,
                 "the source's time at the first row, s (default 0)")
      ->check(CLI::Range(0.0, 1e7));
  add_deviation_options(app, f);
  add_sensor_options(app, f, o);
  CLI11_PARSE(app, argc, argv);

  try {
    if (!o.config.empty()) apply_config(o.config, f);
    f.timing = scp::tools::benchsim::parse_voltage_timing(o.voltage);
    f.clock.rate_error = o.generator_ppm * 1e-6;
    scp::tools::benchsim::apply_noise_level(o.noise, f.sim);
    if (o.noise_x >= 0) f.sim.noise_x = o.noise_x;
    if (o.noise_xdot >= 0) f.sim.noise_xdot = o.noise_xdot;
    if (o.noise_temperature >= 0) f.sim.noise_temperature = o.noise_temperature;
    if (o.no_xdot) f.sim.measure_xdot = false;
    std::ofstream out(o.out, std::ios::binary);
    if (!out) throw std::runtime_error("cannot write " + o.out + "; check the directory exists");
    scp::tools::benchsim::write_bench_file(f, out);
    return 0;
  } catch (const scp::drivers::DriverError& e) {
    std::fprintf(stderr, "scp-benchsim: %s\n", with_flag(e.what()).c_str());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "scp-benchsim: %s\n", e.what());
    return 2;
  }
}

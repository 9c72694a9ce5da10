// scp-crb: the Cramér–Rao bound of θ for the experiment a daemon config describes, and what that
// experiment costs in heating. One JSON object on stdout. See docs/montecarlo.md.
//
//   scp-crb --config config/paper.yaml --duration 300 --noise-x 1e-7 --noise-temperature 1e-3

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <cstdio>
#include <exception>
#include <string>

#include "daemon/config/binder.hpp"
#include "daemon/config/daemon_config.hpp"
#include "tools/crb/crb_report.hpp"
#include "tools/crb/experiment.hpp"

int main(int argc, char** argv) {
  CLI::App app{
      "scp-crb: Cramér–Rao bound of θ for a daemon config's experiment (the simulated plant of "
      "driver.sim, the excitation, loop.period_s), for white noise on x and T"};
  std::string config_path;
  double duration = 300.0;
  double window = 0.0;
  double noise_x = -1.0;
  double noise_temperature = -1.0;
  bool pretty = false;
  scp::tools::crb::TimingUnknowns timing;
  app.add_option("--config", config_path, "daemon config file (driver.type: sim)")->required();
  app.add_option("--duration", duration, "loop time of the experiment in s (default 300)")
      ->check(CLI::Range(1e-3, 1e7));
  app.add_option("--window", window,
                 "bound a fit of the last S seconds (default: the refinement's window, "
                 "refine.window_s, or the whole run when shorter)")
      ->check(CLI::Range(1e-3, 1e7));
  app.add_option("--noise-x", noise_x, "sd of the x sensor in m (default: driver.sim.noise.x)")
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--noise-temperature", noise_temperature,
                 "sd of the T sensor in °C (default: driver.sim.noise.temperature)")
      ->check(CLI::Range(0.0, 100.0));
  app.add_flag("--switch-phases", timing.switch_phases,
               "the excitation's switches fall at phases of their own (a generator on a clock of "
               "its own): bound the phases as unknowns beside θ, as the fit estimates them");
  app.add_flag("--voltage-delay", timing.voltage_delay,
               "the voltage's timing is not known (a replay whose interval the fit estimates, a "
               "live link's refine.link_timing: estimate): bound its delay as one more unknown");
  app.add_flag("--pretty", pretty, "indented JSON");
  CLI11_PARSE(app, argc, argv);

  try {
    const scp::config::DaemonConfig cfg = scp::config::load_config_file(config_path);
    // The refinement fits the last refine.window_s: bound what it sees.
    if (window <= 0.0) window = std::min(duration, cfg.refine.window_s);
    const scp::tools::crb::NoiseLevel noise{
        noise_x >= 0.0 ? noise_x : cfg.driver.sim.noise_x,
        noise_temperature >= 0.0 ? noise_temperature : cfg.driver.sim.noise_temperature};
    const auto experiment = scp::tools::crb::simulate(cfg, duration, window);
    std::array<bool, 6> known{};
    for (std::size_t i = 0; i < 6; ++i) known[i] = cfg.estimator.known[i];
    const auto report = scp::tools::crb::crb_report(
        experiment, noise, known, cfg.actuator.ambient_c, cfg.safety.temperature_max_c,
        cfg.refine.nuisance, cfg.refine.extensions, timing);
    std::printf("%s\n", report.dump(pretty ? 2 : -1).c_str());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "scp-crb: %s\n", e.what());
    return 2;
  }
}

#include "tools/crb/experiment.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

#include "daemon/core/safety.hpp"
#include "drivers/sim/sim_driver.hpp"
#include "excitation/excitation.hpp"

namespace scp::tools::crb {

namespace {

void require(bool ok, const std::string& message) {
  if (!ok) throw std::invalid_argument(message);
}

}  // namespace

Experiment simulate(const config::DaemonConfig& config, double duration_s, double window_s) {
  require(config.driver.type == config::DriverType::sim,
          config.source + ": driver.type is " + config::to_string(config.driver.type) +
              "; the bound needs the simulated plant's parameters (driver.type: sim)");
  require(!drivers::sim::has_drift(config.driver.sim.drift),
          config.source + ": driver.sim.drift is set; the bound is for a constant plant");
  require(config.driver.sim.fault == "none",
          config.source + ": driver.sim.fault is set; the bound is for a healthy sensor");
  require(std::isfinite(duration_s) && duration_s > 0.0, "--duration must be > 0 s");
  require(std::isfinite(window_s) && window_s > 0.0, "--window must be > 0 s");

  // The trajectory without noise: the bound takes the noise level separately.
  drivers::sim::SimSettings sim = config.driver.sim;
  sim.noise_x = sim.noise_xdot = sim.noise_temperature = sim.noise_voltage = 0.0;
  drivers::sim::SimDriver plant(sim);
  plant.open();
  const excitation::Excitation excitation(config.excitation.settings);
  const bool excite = config.excitation.enabled;

  Experiment out;
  out.period_s = config.loop.period_s;
  const auto cycles = static_cast<std::int64_t>(std::llround(duration_s / out.period_s));
  require(cycles >= 2, "--duration must span at least two loop periods");
  out.duration_s = static_cast<double>(cycles) * out.period_s;
  const auto window_cycles = std::min<std::int64_t>(
      cycles, static_cast<std::int64_t>(std::llround(window_s / out.period_s)));
  const std::int64_t first_kept = cycles - window_cycles;
  out.window.reserve(static_cast<std::size_t>(window_cycles + 1));
  const auto theta = drivers::sim::theta_of(sim.plant);
  for (int i = 0; i < 6; ++i) out.theta[i] = theta[static_cast<std::size_t>(i)];
  const drivers::sim::PlantDeviations& d = sim.deviations;
  out.tempcos = {d.resistance_tempco, d.stiffness_softening, d.cooling_tempco};
  out.sensor_lag_s = d.temperature_lag_s;

  double held = 0.0;  // the command the plant holds until the next read (0 V before the first)
  double sum_v = 0.0, sum_v2 = 0.0, sum_tbar = 0.0;
  for (std::int64_t k = 0; k <= cycles; ++k) {
    const double t = static_cast<double>(k) * out.period_s;
    drivers::Sample s;
    const drivers::IoResult read = plant.read(drivers::CycleTime{t, out.period_s}, s);
    require(read.status == drivers::IoStatus::ok, std::string("sim read failed: ") + read.reason);
    const double tbar = s.temperature - sim.ambient_c;
    if (k > 0) {  // the interval (t − period, t] under `held`
      sum_v += held;
      sum_v2 += held * held;
      out.max_voltage = std::max(out.max_voltage, held);
    }
    sum_tbar += tbar;
    out.max_tbar = k == 0 ? tbar : std::max(out.max_tbar, tbar);
    if (k >= first_kept) {
      refine::WindowSample w;
      w.t = t;
      w.x = s.x;
      w.tbar = tbar;
      w.voltage = held;
      w.voltage_since = t - out.period_s;  // the DAC switched at the previous sample instant
      out.window.push_back(w);
      if (k == first_kept) {
        out.initial = refine::InitialState(plant.plant().x(), plant.plant().xdot(), tbar);
      }
    }
    held = excite ? daemon::clamp_voltage(excitation.voltage(t), config.safety) : 0.0;
    plant.write_voltage(held);
  }
  out.mean_voltage = sum_v / static_cast<double>(cycles);
  out.mean_voltage_sq = sum_v2 / static_cast<double>(cycles);
  out.mean_tbar = sum_tbar / static_cast<double>(cycles + 1);
  return out;
}

}  // namespace scp::tools::crb

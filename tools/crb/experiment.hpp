#pragma once
// The noise-free experiment a daemon config describes, as the daemon's loop would run it: the
// simulated plant (driver.sim), the excitation clamped by the safety limit, one read and one write
// per loop period. Its samples are what refine::cramer_rao_bound() needs (the input and the true
// trajectory); its heating figures say what the excitation costs the actuator.

#include <vector>

#include "daemon/config/daemon_config.hpp"
#include "refine/fit.hpp"

namespace scp::tools::crb {

struct Experiment {
  std::vector<refine::WindowSample> window;  // the last window_s of the run, one per period
  refine::InitialState initial = refine::InitialState::Zero();  // x, ẋ, T̄ at window.front()
  refine::Vector6 theta = refine::Vector6::Zero();              // of the simulated plant
  refine::Tempcos tempcos;    // the simulated plant's temperature coefficients (sim.tempco)
  double sensor_lag_s = 0.0;  // its temperature sensor's lag (sim.sensor.temperature_lag_s)
  double period_s = 0.0;
  double duration_s = 0.0;
  // Over the whole run, each command weighted by the period the DAC held it.
  double mean_voltage = 0.0;     // V
  double mean_voltage_sq = 0.0;  // V²: the mean heating is mean_voltage_sq / R
  double max_voltage = 0.0;      // V
  // Sampled once per period over the whole run.
  double mean_tbar = 0.0;  // °C above ambient
  double max_tbar = 0.0;   // °C above ambient
};

// Runs `config` (driver.type sim, no drift, no fault) for duration_s of loop time and keeps the
// samples of the last window_s (all of them when window_s ≥ duration_s). Sample k is read at
// t = k·period after the plant held the previous command over one period, exactly as
// daemon/core/loop.cpp reads and writes; the command at t is clamp_voltage(excitation(t)).
// Throws std::invalid_argument naming the option or key at fault.
Experiment simulate(const config::DaemonConfig& config, double duration_s, double window_s);

}  // namespace scp::tools::crb

#include <algorithm>

#include "daemon/config/daemon_config.hpp"

namespace scp::config {

void derive_settings(DaemonConfig& cfg) {
  auto& est = cfg.estimator;
  est.nominal_period = cfg.loop.period_s;
  // The estimator's input validity follows the safety limits.
  est.x_abs_max = cfg.safety.position_abs_max_m;
  est.tbar_min = cfg.safety.temperature_min_c - cfg.actuator.ambient_c;
  est.tbar_max = cfg.safety.temperature_max_c - cfg.actuator.ambient_c;
  est.voltage_max = std::max(cfg.safety.voltage_max_v, 1e-9) * 1.5;
  cfg.driver.sim.ambient_c = cfg.actuator.ambient_c;
  // The simulated plant's instants are exact; every real link's need estimating.
  cfg.refine.estimate_link_timing =
      cfg.refine.link_timing == LinkTiming::estimate ||
      (cfg.refine.link_timing == LinkTiming::automatic && cfg.driver.type != DriverType::sim);
  // The daemon's own drivers stamp when each voltage took effect (V_since): the interval before.
  switch (cfg.refine.voltage_interval_choice) {
    case VoltageIntervalChoice::after:
      cfg.refine.voltage_interval = scp::refine::VoltageInterval::after;
      break;
    case VoltageIntervalChoice::estimate:
      cfg.refine.voltage_interval = scp::refine::VoltageInterval::estimate;
      break;
    default:
      cfg.refine.voltage_interval = scp::refine::VoltageInterval::before;
  }
  if (cfg.excitation.profile == ExcitationProfile::paper) {
    cfg.excitation.settings = excitation::paper_excitation();
  }
}

}  // namespace scp::config

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
  if (cfg.excitation.profile == ExcitationProfile::paper) {
    cfg.excitation.settings = excitation::paper_excitation();
  }
}

void resolve_voltage_interval(RefineSettings& refine, bool driver_stamps_voltage) noexcept {
  // A user's declaration may be a guess about a file's provenance; a driver's stamps are not.
  refine.check_declared_interval = refine.voltage_interval_choice == VoltageIntervalChoice::after ||
                                   refine.voltage_interval_choice == VoltageIntervalChoice::before;
  switch (refine.voltage_interval_choice) {
    case VoltageIntervalChoice::after:
      refine.voltage_interval = scp::refine::VoltageInterval::after;
      break;
    case VoltageIntervalChoice::estimate:
      refine.voltage_interval = scp::refine::VoltageInterval::estimate;
      break;
    case VoltageIntervalChoice::before:
      refine.voltage_interval = scp::refine::VoltageInterval::before;
      break;
    case VoltageIntervalChoice::automatic:
      // The interval before when the driver stamps when each voltage took effect (V_since);
      // otherwise (a replayed file without that column, perhaps a log of the command issued at
      // t) the refinement estimates it.
      refine.voltage_interval = driver_stamps_voltage ? scp::refine::VoltageInterval::before
                                                      : scp::refine::VoltageInterval::estimate;
  }
}

}  // namespace scp::config

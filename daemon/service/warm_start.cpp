#include "daemon/service/warm_start.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "daemon/service/checkpoints.hpp"
#include "daemon/service/driver_factory.hpp"

namespace scp::daemon {

bool checkpoint_fits(const state::Checkpoint& c, const config::DaemonConfig& config,
                     const std::string& driver_name, std::string& why) {
  if (c.driver != driver_name) {
    why = "it was learned with driver '" + c.driver + "', this daemon runs '" + driver_name +
          "' (another bench's estimate); delete it or set state.warm_start: false";
    return false;
  }
  // Files written before the identity existed carry none; the driver check above is all they get.
  if (!c.actuator.empty() && c.actuator != config.actuator.name) {
    why = "it belongs to actuator '" + c.actuator + "', this daemon is actuator '" +
          config.actuator.name +
          "' (actuator.name); give each actuator its own state.directory, or delete the file "
          "if the name changed on purpose";
    return false;
  }
  if (!c.endpoint.empty() && c.endpoint != driver_endpoint(config)) {
    why = "it was learned through '" + c.endpoint + "', this daemon talks to '" +
          driver_endpoint(config) +
          "' (another device); delete it or set state.warm_start: false if the actuator only "
          "moved to another port";
    return false;
  }
  const auto& est = config.estimator;
  for (std::size_t i = 0; i < c.theta_hat.size(); ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    const double typical = std::max(est.scale[k], std::abs(est.theta0[k]));
    const double limit = config.state.warm_start_theta_max * typical;
    if (!(std::abs(c.theta_hat[i]) <= limit)) {
      char text[256];
      std::snprintf(text, sizeof text,
                    "theta_hat[%zu] = %g is beyond the plausible %g (state.warm_start_theta_max "
                    "x max(estimator.scale, |estimator.theta0|))",
                    i, c.theta_hat[i], limit);
      why = text;
      return false;
    }
  }
  return true;
}

void warm_start(const config::DaemonConfig& cfg, Loop& loop, const std::string& driver_name) {
  if (!cfg.state.warm_start) return;
  const std::string path = checkpoint_path(cfg);
  std::string warning;
  const auto checkpoint = state::load_checkpoint(path, warning);
  if (!checkpoint) {
    if (!warning.empty()) spdlog::warn("{}", warning);
    return;
  }
  std::string why;
  if (!checkpoint_fits(*checkpoint, cfg, driver_name, why)) {
    spdlog::warn("refusing checkpoint {}: {}; starting cold", path, why);
  } else if (loop.restore(to_state(to_view(*checkpoint)))) {
    spdlog::info("warm start from {} (saved at loop time {:.1f} s)", path, checkpoint->t);
  } else {
    spdlog::warn("{}: unusable estimator state; starting cold", path);
  }
}

}  // namespace scp::daemon

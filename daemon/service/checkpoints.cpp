#include "daemon/service/checkpoints.hpp"

#include <spdlog/spdlog.h>

#include <chrono>
#include <filesystem>

#include "common/clock.hpp"
#include "daemon/service/driver_factory.hpp"

namespace scp::daemon {

std::string checkpoint_path(const config::DaemonConfig& cfg) {
  return (std::filesystem::path(cfg.state.directory) / "estimator.state").string();
}

state::Checkpoint to_checkpoint(const EstimatorStateView& v, const std::string& driver,
                                const std::string& actuator, const std::string& endpoint) {
  state::Checkpoint c;
  static_cast<LearnedState&>(c) = v;
  c.driver = driver;
  c.actuator = actuator;
  c.endpoint = endpoint;
  c.wall_time_unix = clock::unix_ns() / clock::kNsPerSecond;
  return c;
}

EstimatorStateView to_view(const state::Checkpoint& c) noexcept {
  EstimatorStateView v;
  static_cast<LearnedState&>(v) = c;
  v.valid = true;
  return v;
}

void save_checkpoint(const config::DaemonConfig& cfg, const EstimatorStateView& view,
                     const std::string& driver_name) {
  if (!view.valid) return;  // nothing learned yet: keep the previous checkpoint
  try {
    state::save_checkpoint(checkpoint_path(cfg), to_checkpoint(view, driver_name, cfg.actuator.name,
                                                               driver_endpoint(cfg)));
    spdlog::debug("checkpoint written to {}", checkpoint_path(cfg));
  } catch (const std::exception& e) {
    spdlog::error("checkpoint failed, the previous one is kept: {}", e.what());
  }
}

}  // namespace scp::daemon

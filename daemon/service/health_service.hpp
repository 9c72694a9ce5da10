#pragma once
// The actuator's health in the service (docs/health.md): the link to the monitor that runs on the
// refinement's worker thread, the baseline file (loaded at start, saved and cleared on request,
// written atomically like a checkpoint and tied to the actuator's name), and the socket server's
// HealthControl.

#include <mutex>
#include <optional>
#include <string>

#include "daemon/analysis/health/health_agent.hpp"
#include "daemon/analysis/health/health_link.hpp"
#include "daemon/config/daemon_config.hpp"
#include "daemon/outputs/server/health_control.hpp"
#include "daemon/service/health_baseline.hpp"

namespace scp::daemon {

class HealthService final : public server::HealthControl {
 public:
  HealthService(const config::DaemonConfig& config, std::string driver_name);

  // The refinement's observer: hand it to the RefineWorker.
  health::HealthAgent& agent() noexcept { return agent_; }

  health::HealthView view() const override { return link_.view().load(); }
  std::uint64_t version() const override { return link_.view().version(); }
  nlohmann::json baseline() const override;
  server::HealthOutcome save_baseline(double now_t) override;
  server::HealthOutcome clear_baseline() override;
  server::HealthOutcome acknowledge(double now_t) override;

 private:
  void use(std::optional<health::Baseline> baseline);

  std::string path_;
  const char* key_;       // the configuration key that says where path_ lies
  bool configured_file_;  // health.baseline.file: made elsewhere, never deleted here
  std::string actuator_;
  std::string driver_;
  health::HealthLink link_;
  health::HealthAgent agent_;
  mutable std::mutex mutex_;  // baseline_: the server thread and start-up
  std::optional<health::Baseline> baseline_;
};

}  // namespace scp::daemon

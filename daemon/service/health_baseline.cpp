#include "daemon/service/health_baseline.hpp"

#include <filesystem>

#include "daemon/service/state/checkpoint.hpp"

namespace scp::daemon {

std::string baseline_path(const config::DaemonConfig& cfg) {
  if (!cfg.health.baseline_file.empty()) return cfg.health.baseline_file;
  return (std::filesystem::path(cfg.state.directory) / (cfg.actuator.name + ".baseline.json"))
      .string();
}

const char* baseline_key(const config::DaemonConfig& cfg) noexcept {
  return cfg.health.baseline_file.empty() ? "state.directory" : "health.baseline.file";
}

std::optional<health::Baseline> load_baseline(const config::DaemonConfig& cfg,
                                              std::string& warning) {
  const std::string path = baseline_path(cfg);
  std::string text;
  if (!state::read_state_file(path, text, warning, kBaselineWhat, baseline_key(cfg))) {
    return std::nullopt;
  }
  std::string error;
  std::optional<health::Baseline> b = health::parse_baseline(text, error);
  if (!b) {
    warning = "baseline " + path + " not used: " + error;
    return std::nullopt;
  }
  // A baseline in the state directory is this actuator's; one named by health.baseline.file
  // was made elsewhere, perhaps under another name.
  if (cfg.health.baseline_file.empty() && b->actuator != cfg.actuator.name) {
    warning = "baseline " + path + " belongs to actuator '" + b->actuator + "', not '" +
              cfg.actuator.name + "'; not used (save a new one)";
    return std::nullopt;
  }
  return b;
}

}  // namespace scp::daemon

#pragma once
// Where the actuator's health baseline is kept and how it is read at start (docs/health.md):
// shared by the service and the batch runs.

#include <optional>
#include <string>

#include "daemon/analysis/health/baseline.hpp"
#include "daemon/config/daemon_config.hpp"

namespace scp::daemon {

// <state.directory>/<actuator.name>.baseline.json, or health.baseline.file.
std::string baseline_path(const config::DaemonConfig& config);
// The key that says where it lies: "health.baseline.file" or "state.directory".
const char* baseline_key(const config::DaemonConfig& config) noexcept;
// What messages call it.
inline constexpr const char* kBaselineWhat = "baseline";

// Reads a baseline; nullopt with `warning` when missing or unusable (a baseline of another
// actuator in the state directory included).
std::optional<health::Baseline> load_baseline(const config::DaemonConfig& config,
                                              std::string& warning);

}  // namespace scp::daemon

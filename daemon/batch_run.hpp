#pragma once
// `scp-estimatord --offline`: the daemon's loop (daemon/loop.cpp) run as fast as it goes, with the
// simulated driver or a replayed CSV, the loop time advancing one period per cycle.

#include <nlohmann/json.hpp>
#include <string>

#include "daemon/config/daemon_config.hpp"

namespace scp::daemon {

struct BatchOptions {
  double duration_s = 200.0;  // loop time to run; a replay also stops at the end of its file
  std::string record_path;    // CSV of every cycle; empty = none
  std::string replay_path;    // CSV to feed instead of the configured driver; empty = none
};

// Runs and returns the summary: t, theta_hat, sigma, (theta_true, rel_error with the simulated
// driver), state, fault_reason, cycles, skipped, wall_time_s, realtime_factor. Throws
// std::runtime_error (driver, recorder) with a message for the user.
nlohmann::json run_batch(config::DaemonConfig config, const BatchOptions& options);

// The human-readable table printed before the JSON line.
std::string summary_table(const nlohmann::json& summary);

}  // namespace scp::daemon

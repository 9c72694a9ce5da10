#pragma once
// `scp-estimatord --offline`: the daemon's loop (daemon/core/loop.cpp) run as fast as it goes, with
// the simulated driver or a replayed CSV, the loop time advancing one period per cycle.

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "daemon/config/daemon_config.hpp"

namespace scp::daemon {

inline constexpr double kDefaultBatchDuration = 200.0;  // s, without a replay

struct BatchOptions {
  // Loop time to run. Unset: a replay runs to the end of its file, a simulation
  // kDefaultBatchDuration. A replay also stops at the end of its file when this is longer.
  std::optional<double> duration_s;
  std::string record_path;  // CSV of every cycle; empty = none
  // CSV files (or directories of them, e.g. a rotated recording) to feed, in time order, instead
  // of the configured driver; empty = none.
  std::vector<std::string> replay_paths;
};

// Runs and returns the summary: t, theta_hat, sigma, (theta_true, rel_error with the simulated
// driver), state, fault_reason, cycles, skipped, wall_time_s, realtime_factor, and with refine
// enabled paper_biased, best, refined (as in ESTIMATE) and refine counters. The refinement runs
// inline: a fit every refine.interval_s of loop time and one at the end. Throws
// std::runtime_error (driver, recorder) with a message for the user.
nlohmann::json run_batch(config::DaemonConfig config, const BatchOptions& options);

// The human-readable table printed before the JSON line.
std::string summary_table(const nlohmann::json& summary);

}  // namespace scp::daemon

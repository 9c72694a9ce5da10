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
  // Fits made at once on worker threads beside the loop (parallel_refinement.hpp); 1 = inline
  // between the loop's cycles, as the refinement ran before; 0 = one per core.
  unsigned jobs = 0;
};

// Runs and returns the summary: t, theta_hat, sigma, (theta_true, rel_error with the simulated
// driver), state, fault_reason, cycles, skipped, wall_time_s, realtime_factor, and with refine
// enabled paper_biased, best, refined (as in ESTIMATE) and refine counters. The refinement makes
// a fit every refine.interval_s of loop time and one at the end, inline or on options.jobs
// worker threads; either way the same file gives the same summary every run. Throws
// std::runtime_error (driver, recorder) with a message for the user.
nlohmann::json run_batch(config::DaemonConfig config, const BatchOptions& options);

// The human-readable table printed before the JSON line.
std::string summary_table(const nlohmann::json& summary);

}  // namespace scp::daemon

#pragma once
// Estimator checkpoints: what the daemon saves periodically and on shutdown so that a restart
// resumes from the learned parameters instead of from scratch ("warm start").
//
// File format (JSON, one object):
//   {"format":"scp-estimator-state", "version":1, "theta_hat":[6], "info_mech":[16],
//    "info_thermal":[4], "eps2_mean":[2], "t":s, "driver":"sim", "wall_time_unix":s,
//    "actuator":"bench-a", "endpoint":"modbus tcp 10.0.0.5:502",
//    "checksum":"fnv1a64:<16 hex digits>"}
// "actuator" and "endpoint" (the actuator's identity) are optional on load: files written before
// they existed read as "" and are judged by the driver alone.
// The checksum is FNV-1a (64 bit) over the compact JSON dump of every other field (keys sorted),
// so a torn or hand-edited file is recognised and ignored instead of seeding the estimator with
// garbage.

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "daemon/core/learned_state.hpp"

namespace scp::daemon::state {

using daemon::LearnedState;

inline constexpr std::string_view kCheckpointFormat = "scp-estimator-state";
inline constexpr int kCheckpointVersion = 1;

// The estimator's learned state (t: loop time when saved) and whose it is.
struct Checkpoint : LearnedState {
  std::string driver;               // driver name the estimate was learned with
  std::int64_t wall_time_unix = 0;  // s since the epoch when saved
  std::string actuator;             // actuator.name ("" in files written before it)
  std::string endpoint;             // the device the driver talked to ("" likewise)
};

// Writes atomically: path.tmp.<pid>, fsync, rename over `path`, fsync the directory. Throws
// std::runtime_error naming the path and the errno text on any failure (ENOSPC, EACCES, ...),
// in which case the previous file at `path` is untouched and no temporary file is left behind.
// After a successful save, temporaries left by crashed earlier processes (path.tmp.<dead pid>)
// are removed.
// Also throws if a field is non-finite (a diverged estimate must not be persisted).
void save_checkpoint(const std::string& path, const Checkpoint& checkpoint);

// Returns the checkpoint, or nullopt with `warning` naming the problem (missing, unreadable,
// truncated or not JSON, wrong format or version, bad checksum, missing or non-finite fields,
// information matrices not symmetric positive definite). Never throws for bad file contents.
std::optional<Checkpoint> load_checkpoint(const std::string& path, std::string& warning);

// The same atomic write and guarded read for the other small state files (the health baseline):
// write_state_file throws std::runtime_error naming the path; read_state_file returns false with
// `reason` (missing, not a regular file, not ours, too large). The messages call the file `what`
// ("baseline") and name `key`, the configuration key that says where it lies.
void write_state_file(const std::string& path, const std::string& data, std::string_view what,
                      std::string_view key);
bool read_state_file(const std::string& path, std::string& out, std::string& reason,
                     std::string_view what, std::string_view key);

// FNV-1a, 64 bit (exposed for tests).
std::uint64_t fnv1a64(std::string_view data) noexcept;

}  // namespace scp::daemon::state

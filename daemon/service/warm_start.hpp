#pragma once
// Whether a checkpoint may seed this daemon's estimator. The file's checksum proves it is intact,
// not that it belongs here: one learned on another driver (another bench) or holding absurd
// values (a poisoned or diverged θ̂ with a valid checksum runs, with absurd prediction errors)
// must be refused, and the daemon starts cold.

#include <string>

#include "daemon/config/daemon_config.hpp"
#include "daemon/core/loop.hpp"
#include "daemon/service/state/checkpoint.hpp"

namespace scp::daemon {

// True when usable; otherwise false with `why` naming the field and the remedy.
bool checkpoint_fits(const state::Checkpoint& checkpoint, const config::DaemonConfig& config,
                     const std::string& driver_name, std::string& why);

// Before the first cycle, with state.warm_start: restores the checkpoint into `loop` when it fits
// this actuator and driver; otherwise logs why and the loop starts cold.
void warm_start(const config::DaemonConfig& config, Loop& loop, const std::string& driver_name);

}  // namespace scp::daemon

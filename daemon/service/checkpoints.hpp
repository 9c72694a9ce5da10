#pragma once
// What the estimator learned, kept across restarts: the loop's published state written to
// <state.directory>/estimator.state (atomically, checksummed: state/checkpoint.hpp) every
// state.checkpoint_interval_s and at shutdown; read back at start by warm_start.hpp.

#include <string>

#include "daemon/config/daemon_config.hpp"
#include "daemon/core/estimator_state.hpp"
#include "daemon/service/state/checkpoint.hpp"

namespace scp::daemon {

std::string checkpoint_path(const config::DaemonConfig& config);

// `actuator` and `endpoint` identify the actuator the estimate belongs to (warm_start.hpp).
state::Checkpoint to_checkpoint(const EstimatorStateView& view, const std::string& driver,
                                const std::string& actuator, const std::string& endpoint);
EstimatorStateView to_view(const state::Checkpoint& checkpoint) noexcept;

// Writes `view` unless it is empty (nothing learned yet); a failed write is logged and the
// previous file kept.
void save_checkpoint(const config::DaemonConfig& config, const EstimatorStateView& view,
                     const std::string& driver_name);

}  // namespace scp::daemon

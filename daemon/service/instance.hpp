#pragma once
// scp-estimatord --instance NAME (the template unit scp-estimatord@NAME.service): one daemon per
// actuator on a PC, each with its own socket, state directory and name, decided by the instance
// so that two configurations copied from one another cannot share them by mistake.

#include <string>
#include <vector>

#include "daemon/config/daemon_config.hpp"
#include "daemon/programs/cli/instance_names.hpp"

namespace scp::daemon {

using cli::instance_name_problem;
using cli::instance_socket;

// Sets socket.path and state.directory from the instance, and actuator.name when the file left
// it at its default. Returns a warning for each key the file set to something else (ignored).
std::vector<std::string> apply_instance(config::DaemonConfig& config, const std::string& name);

}  // namespace scp::daemon

#pragma once
// scp-estimatord --instance NAME (the template unit scp-estimatord@NAME.service): one daemon per
// actuator on a PC, each with its own socket, state directory and name, decided by the instance
// so that two configurations copied from one another cannot share them by mistake.

#include <string>
#include <vector>

#include "daemon/config/daemon_config.hpp"

namespace scp::daemon {

inline constexpr const char* kRunDirectory = "/run/scp-estimator";
inline constexpr const char* kStateRoot = "/var/lib/scp-estimator";

// "" when `name` may name an instance (1-64 letters, digits, '.', '_', '-'; not "." or ".."),
// else why not.
std::string instance_name_problem(const std::string& name);

std::string instance_socket(const std::string& name);  // /run/scp-estimator/NAME.sock

// Sets socket.path and state.directory from the instance, and actuator.name when the file left
// it at its default. Returns a warning for each key the file set to something else (ignored).
std::vector<std::string> apply_instance(config::DaemonConfig& config, const std::string& name);

}  // namespace scp::daemon

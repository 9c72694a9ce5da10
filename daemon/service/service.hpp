#pragma once
// The daemon proper: real-time loop thread, socket server, checkpoints, systemd notification,
// signals. Returns the process exit code.

#include "daemon/config/daemon_config.hpp"

namespace scp::daemon {

int run_service(const config::DaemonConfig& config);

}  // namespace scp::daemon

#pragma once
// scp-estimatord as a service: the start-up (state lock, driver, loop, warm start, socket, device,
// loop thread, systemd READY), the main thread's watch (signals, reload, the journal's account of
// the loop, the start timeout, metrics, checkpoints) and the shutdown to 0 V. Returns the process
// exit code.

#include "daemon/config/daemon_config.hpp"

namespace scp::daemon {

int run_service(const config::DaemonConfig& config);

}  // namespace scp::daemon

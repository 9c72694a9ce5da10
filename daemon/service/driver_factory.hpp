#pragma once
// The drivers the daemon is built with: `driver.type` in the config picks one.

#include <memory>
#include <string>

#include "daemon/config/daemon_config.hpp"
#include "drivers/driver.hpp"

namespace scp::daemon {

// Throws drivers::DriverError (the driver's own, naming the setting and the remedy).
std::unique_ptr<drivers::Driver> make_driver(const config::DaemonConfig& config);

// The device this configuration talks to, in words ("modbus tcp 10.0.0.5:502", "can can0",
// "replay /path.csv", "sim"): part of a checkpoint's identity, so that a warm start through
// another device is refused.
std::string driver_endpoint(const config::DaemonConfig& config);

}  // namespace scp::daemon

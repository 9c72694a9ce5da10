#pragma once
// What the binder cannot see in one key: facts about the machine that would stop the daemon at
// start-up (a group, a file, a directory), and values that are valid alone but almost certainly
// a slip (a temperature limit in kelvin, an excitation above the voltage limit). Run by
// `scp-estimatord --check-config` and, for the warnings, at start-up.

#include <string>
#include <vector>

#include "daemon/config/daemon_config.hpp"

namespace scp::config {

struct Finding {
  enum class Severity { error, warning };
  Severity severity;
  std::string key;      // "socket.group"
  std::string message;  // says the remedy
};

// Findings about the running machine (errors) and suspicious values (warnings).
std::vector<Finding> startup_findings(const DaemonConfig& config);

// "FILE:LINE: key: message" (LINE when `config.source` is a file that sets the key).
std::string describe(const DaemonConfig& config, const Finding& finding);

}  // namespace scp::config

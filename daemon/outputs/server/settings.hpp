#pragma once
// What the daemon tells the socket server at construction: where to listen, who may command, and
// the limits that keep one misbehaving client from hurting the others (docs/protocol.md).

#include <cstddef>
#include <string>

namespace scp::daemon::server {

struct ServerSettings {
  std::string socket_path = "/run/scp-estimator/scp-estimator.sock";
  std::string group;  // "" = none: only root and the daemon's own user may send commands
  unsigned mode = 0660;
  std::size_t max_clients = 128;
  std::size_t max_line = 4096;
  double idle_timeout_s = 300;
  std::size_t max_output_bytes = 1 << 20;
  // Connections beyond max_clients kept for privileged peers (root, the daemon's user, `group`),
  // so that a local user holding every ordinary slot cannot lock the operator out of
  // `excitation off`.
  std::size_t privileged_reserve = 8;
  // Unsent output of all clients together stays below this: each client's cap is
  // min(max_output_bytes, output_budget_bytes / (max_clients + privileged_reserve)).
  std::size_t output_budget_bytes = 16u << 20;
};

// Facts that do not change while the daemon runs, repeated in every STATUS reply.
struct ServerInfo {
  std::string release;
  std::string driver;
  std::string config_file;  // "" when running on defaults
  std::string actuator;     // actuator.name ("" in tests: omitted)
};

}  // namespace scp::daemon::server

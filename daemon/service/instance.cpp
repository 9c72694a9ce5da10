#include "daemon/service/instance.hpp"

namespace scp::daemon {

namespace {

const config::DaemonConfig& defaults() {
  static const config::DaemonConfig cfg;
  return cfg;
}

}  // namespace

std::vector<std::string> apply_instance(config::DaemonConfig& config, const std::string& name) {
  std::vector<std::string> warnings;
  const std::string socket = instance_socket(name);
  const std::string state = std::string(cli::kStateRoot) + "/" + name;
  if (config.socket.socket_path != defaults().socket.socket_path &&
      config.socket.socket_path != socket) {
    warnings.push_back("socket.path " + config.socket.socket_path + " is ignored: instance " +
                       name + " listens on " + socket);
  }
  if (config.state.directory != defaults().state.directory && config.state.directory != state) {
    warnings.push_back("state.directory " + config.state.directory + " is ignored: instance " +
                       name + " keeps its state in " + state);
  }
  config.socket.socket_path = socket;
  config.state.directory = state;
  if (config.actuator.name == defaults().actuator.name) config.actuator.name = name;
  return warnings;
}

}  // namespace scp::daemon

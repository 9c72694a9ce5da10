#include "daemon/config/startup_checks.hpp"

#include <grp.h>
#include <sys/stat.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <cerrno>
#include <cstring>
#include <sstream>

#include "common/checks.hpp"
#include "drivers/modbus/timing.hpp"

namespace scp::config {

namespace {

using checks::num;

bool group_exists(const std::string& name) {
  std::vector<char> buffer(16384);
  group entry{};
  group* found = nullptr;
  if (getgrnam_r(name.c_str(), &entry, buffer.data(), buffer.size(), &found) == 0 && found)
    return true;
  // A numeric gid is accepted by the daemon as it is (peer_auth.cpp: resolve_group).
  return !name.empty() && name.find_first_not_of("0123456789") == std::string::npos;
}

void check_group(const DaemonConfig& cfg, std::vector<Finding>& out) {
  const std::string& name = cfg.socket.group;
  if (name.empty() || group_exists(name)) return;
  out.push_back({Finding::Severity::error, "socket.group",
                 "group '" + name + "' does not exist, so the daemon cannot start; create it " +
                     "(groupadd --system " + name + ") or set socket.group to \"\""});
}

void check_replay(const DaemonConfig& cfg, std::vector<Finding>& out) {
  if (cfg.driver.type != DriverType::replay) return;
  const std::string& file = cfg.driver.replay.file;
  if (::access(file.c_str(), R_OK) != 0) {
    out.push_back({Finding::Severity::error, "driver.replay.file",
                   "cannot read '" + file + "' (" + std::strerror(errno) +
                       "), so the daemon cannot start; name an existing CSV (t,x,xdot,T,V)"});
  }
}

void check_state_directory(const DaemonConfig& cfg, std::vector<Finding>& out) {
  const std::string& dir = cfg.state.directory;
  struct stat st {};
  if (::stat(dir.c_str(), &st) != 0) {
    out.push_back({Finding::Severity::error, "state.directory",
                   "'" + dir + "' does not exist (" + std::strerror(errno) +
                       "), so no checkpoint can be written; create it, owned by the daemon's "
                       "user (systemd-tmpfiles --create scp-estimator.conf does for the default)"});
    return;
  }
  if (!S_ISDIR(st.st_mode)) {
    out.push_back({Finding::Severity::error, "state.directory",
                   "'" + dir + "' is not a directory; name a directory for the checkpoints"});
    return;
  }
  if (::access(dir.c_str(), W_OK | X_OK) != 0) {
    out.push_back({Finding::Severity::error, "state.directory",
                   "'" + dir + "' is not writable by uid " + std::to_string(::geteuid()) +
                       ", so no checkpoint can be written; give it to the daemon's user "
                       "(chown scp-estimator: " +
                       dir + ") or run --check-config as that user"});
  }
}

// The daemon binds socket.path at start and does not create its directory. The unit's
// RuntimeDirectory= makes /run/scp-estimator when the service starts, so that one may be missing.
void check_socket_directory(const DaemonConfig& cfg, std::vector<Finding>& out) {
  const std::string& path = cfg.socket.socket_path;
  const auto slash = path.rfind('/');
  if (slash == std::string::npos || slash == 0) return;
  const std::string dir = path.substr(0, slash);
  if (dir == "/run/scp-estimator") return;
  struct stat st {};
  if (::stat(dir.c_str(), &st) != 0 || !S_ISDIR(st.st_mode)) {
    out.push_back({Finding::Severity::error, "socket.path",
                   "the directory '" + dir + "' does not exist, so the daemon cannot create its " +
                       "socket; create it or choose another socket.path"});
  }
}

void check_suspicious_values(const DaemonConfig& cfg, std::vector<Finding>& out) {
  // SCP (nylon) actuators soften above ~150 °C and melt near 250 °C; a limit above that is
  // almost always a temperature written in kelvin.
  constexpr double kKelvinLike = 250.0;
  const double t_max = cfg.safety.temperature_max_c;
  if (t_max >= kKelvinLike) {
    out.push_back({Finding::Severity::warning, "safety.temperature_max_c",
                   num(t_max) +
                       " °C is above the melting point of nylon (~250 °C): is it in "
                       "kelvin? " +
                       num(t_max) + " K would be " + num(t_max - 273.15) +
                       " °C; the key is in °C"});
  }
  const double v_max = cfg.excitation.settings.v_max;
  const double limit = cfg.safety.voltage_max_v;
  if (v_max > limit) {
    out.push_back(
        {Finding::Severity::warning, "excitation.v_max",
         num(v_max) + " V is above safety.voltage_max_v " + num(limit) +
             " V: the safety clamp cuts the excitation at " + num(limit) +
             " V, which distorts its spectrum; lower excitation.v_max or raise the limit"});
  }
  if (cfg.driver.type == DriverType::modbus) {
    for (std::string& text :
         drivers::modbus::line_timing_warnings(cfg.driver.modbus, cfg.loop.period_s))
      out.push_back(
          {Finding::Severity::warning, "driver.modbus.response_timeout", std::move(text)});
  }
}

// Line of a dotted key in the YAML file, or 0.
int line_of(const std::string& file, const std::string& dotted) {
  try {
    YAML::Node node = YAML::LoadFile(file);
    std::stringstream path(dotted);
    std::string part;
    YAML::Mark mark;
    bool found = false;
    while (std::getline(path, part, '.')) {
      if (!node.IsMap()) return 0;
      found = false;
      for (auto it = node.begin(); it != node.end(); ++it) {
        if (it->first.IsScalar() && it->first.Scalar() == part) {
          mark = it->first.Mark();
          node.reset(it->second);
          found = true;
          break;
        }
      }
      if (!found) return 0;
    }
    return found && mark.line >= 0 ? mark.line + 1 : 0;
  } catch (const std::exception&) {
    return 0;
  }
}

}  // namespace

std::vector<Finding> startup_findings(const DaemonConfig& config) {
  std::vector<Finding> out;
  check_group(config, out);
  check_replay(config, out);
  check_state_directory(config, out);
  check_socket_directory(config, out);
  check_suspicious_values(config, out);
  return out;
}

std::string describe(const DaemonConfig& config, const Finding& finding) {
  std::string out = config.source.empty() ? "(defaults)" : config.source;
  if (!config.source.empty()) {
    if (const int line = line_of(config.source, finding.key); line > 0) {
      out += ':';
      out += std::to_string(line);
    }
  }
  return out + ": " + finding.key + ": " + finding.message;
}

}  // namespace scp::config

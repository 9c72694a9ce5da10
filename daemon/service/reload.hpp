#pragma once
// SIGHUP (systemctl reload): which keys of the configuration file changed since the start, which
// of them the running daemon applies, and which need a restart. Pure: no threads, no logging.

#include <string>
#include <vector>

#include "daemon/config/daemon_config.hpp"

namespace scp::daemon {

// Keys applied while running: log_level, the safety limits (the loop reads them through a
// seqlock each period), the excitation (handed to the loop over a ring), the recording (a new
// recorder on the same ring) and the metrics textfile (the main thread's own).
bool reloadable(const std::string& key);
// True when `key` is `section` or one of its keys ("excitation.offset_v" is in "excitation").
bool in_section(const std::string& key, const std::string& section);

// Dotted keys ("safety.temperature_max_c") whose values differ between two YAML texts (a key
// present in one only counts as changed); a list is compared as a whole.
std::vector<std::string> changed_keys(const std::string& before, const std::string& after);

struct ReloadPlan {
  config::DaemonConfig fresh;        // the new file, fully validated
  std::string text;                  // the new file's text (the next reload compares with it)
  std::vector<std::string> applied;  // reloadable keys changed since the last applied file
  std::vector<std::string> restart;  // other keys changed since the start: restart needed
  // Which sections changed among the applied keys.
  bool excitation = false;
  bool recording = false;
  bool metrics = false;
  bool safety = false;
};

// Reads and validates `path` as at start-up; throws (config::ConfigError) when the file is
// invalid, so that the caller keeps the running configuration entirely. `started_text` is the
// file the daemon started with (restart-only keys are compared with it), `applied_text` the last
// one applied (the start's, or the last successful reload's).
ReloadPlan plan_reload(const std::string& path, const std::string& started_text,
                       const std::string& applied_text);

}  // namespace scp::daemon

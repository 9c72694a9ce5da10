#pragma once
// The daemon's account of what the loop did, written by the service thread from the snapshots the
// loop publishes (the loop itself never logs): one line per fault (err), per state change and
// recovery (notice), per link loss (warning) and reconnection (notice). Faults that came and went
// between two snapshots are found through the loop's fault counter, so none goes unlogged.

#include <optional>
#include <string>

#include "daemon/core/published_state.hpp"
#include "drivers/driver.hpp"

namespace scp::daemon {

class EventLog {
 public:
  explicit EventLog(const PublishedState& initial) : last_(initial) {}

  // Logs what changed since the previous call. Returns the new text for systemd's STATUS= when
  // the state changed.
  std::optional<std::string> observe(const PublishedState& now, const drivers::Driver& driver);

 private:
  void driver_changes(const drivers::DriverStats& now, const drivers::Driver& driver);

  PublishedState last_;
  std::string last_reconnect_error_;
};

// How the output stands, in words for the log.
std::string output_text(const drivers::DriverStats& d);

}  // namespace scp::daemon

#include "daemon/outputs/server/audit.hpp"

#include <spdlog/spdlog.h>

#include <ctime>

#include "daemon/outputs/log/journal_log.hpp"
#include "daemon/outputs/server/render.hpp"

namespace scp::daemon::server {

std::string audit_text(const CommandRecord& record) {
  std::string who = "a peer of unknown identity";
  if (record.peer) {
    who = "uid " + std::to_string(record.peer->uid) + " gid " + std::to_string(record.peer->gid) +
          " pid " + std::to_string(record.peer->pid);
  }
  std::string text =
      "command '" + record.name + "' from " + who + ": " + outcome_name(record.outcome);
  if (!record.message.empty()) text += " (" + record.message + ")";
  return text;
}

void log_audit(const CommandRecord& record) {
  if (record.outcome == CommandOutcome::done) {
    log::notice("{}", audit_text(record));
  } else {
    spdlog::warn("{}", audit_text(record));
  }
}

void put_last_command(nlohmann::json& out, const CommandRecord& record) {
  nlohmann::json c = {{"name", record.name}, {"outcome", outcome_name(record.outcome)}};
  if (record.peer) {
    c["uid"] = record.peer->uid;
    c["gid"] = record.peer->gid;
    c["pid"] = record.peer->pid;
  }
  put_wall_clock(c, record.unix_ns);
  if (!record.message.empty()) c["message"] = record.message;
  out["last_command"] = c;
}

}  // namespace scp::daemon::server

#pragma once
// The audit trail of mutating requests (docs/protocol.md, "Audit trail"): who asked (the kernel's
// SO_PEERCRED uid, gid and pid), what, when, and what came of it, refused requests included. Each
// outcome is one log line (notice when carried out, warning otherwise) and the latest is shown
// in STATUS as "last_command".

#include <sys/types.h>

#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "common/names.hpp"
#include "daemon/outputs/server/peer_auth.hpp"

namespace scp::daemon::server {

enum class CommandOutcome {
  done,     // the loop carried it out
  failed,   // the loop refused it (e.g. clear-fault while the cause persists)
  refused,  // the peer is not privileged
  busy,     // the command queue was full
  timeout,  // the loop did not answer in time
};

inline constexpr NameTable<CommandOutcome, 5> kCommandOutcomeNames{
    {{CommandOutcome::done, "done"},
     {CommandOutcome::failed, "failed"},
     {CommandOutcome::refused, "refused"},
     {CommandOutcome::busy, "busy"},
     {CommandOutcome::timeout, "timeout"}}};

constexpr const char* outcome_name(CommandOutcome outcome) noexcept {
  return name_of(kCommandOutcomeNames, outcome);
}

struct CommandRecord {
  std::string name;                  // "excitation off", "reset", "clear-fault"
  std::optional<PeerIdentity> peer;  // nullopt when the kernel reported nothing
  std::int64_t unix_ns = 0;          // CLOCK_REALTIME when the request arrived
  CommandOutcome outcome = CommandOutcome::done;
  std::string message;  // the loop's or the server's words
};

// "command 'excitation off' from uid 1000 gid 1000 pid 4242: done (excitation off: ...)"
std::string audit_text(const CommandRecord& record);

// One line: notice when done, warning otherwise.
void log_audit(const CommandRecord& record);

// STATUS "last_command": {name, outcome, uid, gid, pid, utc, unix_ns, message}.
void put_last_command(nlohmann::json& out, const CommandRecord& record);

}  // namespace scp::daemon::server

#pragma once
// Who is on the other end of a client socket, and whether that peer may send mutating requests
// (docs/protocol.md, "Privileges"). Monitoring is open to anyone who can connect; control is kept
// to root, the daemon's own user and one configured group, as chrony and linuxptp separate them.

#include <sys/types.h>

#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace scp::daemon::server {

// The kernel's view of the peer at connect time (SO_PEERCRED, SO_PEERGROUPS).
struct PeerIdentity {
  pid_t pid = -1;
  uid_t uid = static_cast<uid_t>(-1);
  gid_t gid = static_cast<gid_t>(-1);
  std::vector<gid_t> groups;  // supplementary groups
};

struct AuthPolicy {
  uid_t daemon_uid = 0;
  std::optional<gid_t> group;  // the configured socket.group, resolved
  std::string group_name;      // for messages
};

bool is_privileged(const PeerIdentity& peer, const AuthPolicy& policy) noexcept;

// The ERROR text for a refused request, naming the remedy.
std::string permission_denied_message(std::string_view request, const AuthPolicy& policy);

// Reads SO_PEERCRED and the supplementary groups (SO_PEERGROUPS, falling back to the Groups: line
// of /proc/<pid>/status on kernels without it). nullopt when the kernel reports nothing.
std::optional<PeerIdentity> peer_identity(int fd);

// Parses the "Groups:" line of a /proc/<pid>/status text.
std::vector<gid_t> parse_proc_status_groups(std::string_view status_text);

// Resolves a group name (or a decimal gid); throws std::runtime_error naming the remedy.
gid_t resolve_group(const std::string& name);

}  // namespace scp::daemon::server

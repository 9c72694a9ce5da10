#include "daemon/outputs/server/peer_auth.hpp"

#include <grp.h>
#include <sys/socket.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <fstream>
#include <sstream>
#include <stdexcept>

#ifndef SO_PEERGROUPS
#define SO_PEERGROUPS 59  // Linux >= 4.13; older headers lack the constant
#endif

namespace scp::daemon::server {

bool is_privileged(const PeerIdentity& peer, const AuthPolicy& policy) noexcept {
  if (peer.uid == 0 || peer.uid == policy.daemon_uid) return true;
  if (!policy.group) return false;
  if (peer.gid == *policy.group) return true;
  return std::find(peer.groups.begin(), peer.groups.end(), *policy.group) != peer.groups.end();
}

std::string permission_denied_message(std::string_view request, const AuthPolicy& policy) {
  std::string message = "permission denied: '" + std::string(request) +
                        "' changes the daemon's state and needs root, the daemon's user";
  if (policy.group) {
    message += " or group '" + policy.group_name + "'; add the user to group " + policy.group_name +
               " (usermod -aG " + policy.group_name + " USER, then log in again)";
  } else {
    message +=
        "; run it with sudo, or set socket.group in the daemon's configuration and add the "
        "user to that group";
  }
  return message;
}

std::vector<gid_t> parse_proc_status_groups(std::string_view status_text) {
  std::vector<gid_t> groups;
  constexpr std::string_view kKey = "Groups:";
  std::size_t pos = 0;
  while (pos < status_text.size()) {
    std::size_t end = status_text.find('\n', pos);
    if (end == std::string_view::npos) end = status_text.size();
    const std::string_view row = status_text.substr(pos, end - pos);
    if (row.substr(0, kKey.size()) == kKey) {
      const char* p = row.data() + kKey.size();
      const char* last = row.data() + row.size();
      while (p < last) {
        while (p < last && (*p == ' ' || *p == '\t')) ++p;
        if (p == last) break;
        unsigned long value = 0;
        const auto [next, ec] = std::from_chars(p, last, value);
        if (ec != std::errc{}) break;
        groups.push_back(static_cast<gid_t>(value));
        p = next;
      }
      break;
    }
    pos = end + 1;
  }
  return groups;
}

std::optional<PeerIdentity> peer_identity(int fd) {
  ucred cred{};
  socklen_t len = sizeof(cred);
  if (getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &cred, &len) != 0 || len != sizeof(cred))
    return std::nullopt;
  PeerIdentity peer;
  peer.pid = cred.pid;
  peer.uid = cred.uid;
  peer.gid = cred.gid;

  std::vector<gid_t> groups(32);
  for (int attempt = 0; attempt < 4; ++attempt) {
    socklen_t bytes = static_cast<socklen_t>(groups.size() * sizeof(gid_t));
    if (getsockopt(fd, SOL_SOCKET, SO_PEERGROUPS, groups.data(), &bytes) == 0) {
      groups.resize(bytes / sizeof(gid_t));
      peer.groups = std::move(groups);
      return peer;
    }
    if (errno != ERANGE) break;
    // The kernel reports the size it needs.
    groups.resize(bytes / sizeof(gid_t) + 1);
  }
  // Old kernel: the process's current groups are the best we can do (racy against the pid
  // exiting, in which case the peer simply gets no supplementary groups).
  std::ifstream status("/proc/" + std::to_string(cred.pid) + "/status");
  if (status) {
    std::stringstream text;
    text << status.rdbuf();
    peer.groups = parse_proc_status_groups(text.str());
  }
  return peer;
}

gid_t resolve_group(const std::string& name) {
  std::vector<char> buffer(16384);
  group entry{};
  group* found = nullptr;
  const int rc = getgrnam_r(name.c_str(), &entry, buffer.data(), buffer.size(), &found);
  if (rc == 0 && found != nullptr) return found->gr_gid;
  unsigned long numeric = 0;
  const auto [end, ec] = std::from_chars(name.data(), name.data() + name.size(), numeric);
  if (!name.empty() && ec == std::errc{} && end == name.data() + name.size())
    return static_cast<gid_t>(numeric);
  throw std::runtime_error("socket.group: group '" + name +
                           "' does not exist; create it (groupadd " + name +
                           ") or set socket.group to \"\"");
}

}  // namespace scp::daemon::server

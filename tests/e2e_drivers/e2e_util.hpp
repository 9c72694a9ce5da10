#pragma once
// Helpers of the end-to-end tests: child processes (killed by pid when the test ends, even on
// failure), an inherited descriptor for the CAN tests, temp directories, the daemon's socket,
// and the configurations the daemon and scp-simdaq share.

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/types.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "tests/support/child_process.hpp"

namespace scp::test {

inline const std::string kDaemon = SCP_DAEMON_PATH;
inline const std::string kSimdaq = SCP_SIMDAQ_PATH;

// Real-time runs: scp-simdaq and socat stand in for hardware that answers in bounded time, so as
// root they run SCHED_FIFO 60, below the daemon's loop (80); a loaded CI machine then delays
// neither of them by whole milliseconds. Without root they run ordinarily.
inline constexpr int kPeerPriority = 60;
inline std::vector<std::string> simdaq_realtime(std::vector<std::string> args) {
  args.insert(args.begin(), kSimdaq);
  if (geteuid() == 0) {
    args.push_back("--priority");
    args.push_back(std::to_string(kPeerPriority));
  }
  return args;
}
inline std::vector<std::string> with_realtime_priority(std::vector<std::string> argv) {
  if (geteuid() == 0)
    argv.insert(argv.begin(), {"/usr/bin/chrt", "-f", std::to_string(kPeerPriority)});
  return argv;
}

// A temporary directory removed at the end of the test.
class TempDir {
 public:
  TempDir() {
    std::string tmpl = (std::filesystem::temp_directory_path() / "scp-e2e-XXXXXX").string();
    if (mkdtemp(tmpl.data()) != nullptr) path_ = tmpl;
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::filesystem::path& path() const { return path_; }
  std::string file(const std::string& name) const { return (path_ / name).string(); }
  std::string write(const std::string& name, const std::string& text) const {
    std::ofstream(file(name)) << text;
    return file(name);
  }

 private:
  std::filesystem::path path_;
};

// A socketpair standing in for a CAN bus (the kernel here has no SocketCAN): SEQPACKET keeps one
// can_frame per message, as a CAN_RAW socket does. Both ends close-on-exec; ChildProcess passes one
// on.
struct CanWire {
  int daemon = -1;
  int node = -1;
  CanWire() {
    int fds[2];
    if (socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, fds) == 0) {
      daemon = fds[0];
      node = fds[1];
    }
  }
  ~CanWire() {
    if (daemon >= 0) ::close(daemon);
    if (node >= 0) ::close(node);
  }
  CanWire(const CanWire&) = delete;
  CanWire& operator=(const CanWire&) = delete;
};

// The port scp-simdaq printed ("listening on 127.0.0.1:PORT"), or -1.
inline int printed_port(const std::string& out) {
  const auto at = out.find("listening on 127.0.0.1:");
  if (at == std::string::npos) return -1;
  return std::atoi(out.c_str() + at + 23);
}

// The two pty names socat printed ("PTY is /dev/pts/N").
inline std::vector<std::string> printed_ptys(const std::string& out) {
  std::vector<std::string> ptys;
  std::size_t at = 0;
  while ((at = out.find("PTY is ", at)) != std::string::npos) {
    at += 7;
    const auto end = out.find_first_of("\r\n", at);
    ptys.push_back(out.substr(at, end - at));
  }
  return ptys;
}

// One line "step,wall_s,volts[,note]" per command the peer received. note: "" = applied,
// "unanswered" = received in a dead-slave window and not applied, "watchdog" = the peer's own
// communication watchdog set the output to 0 V.
struct LoggedCommand {
  long long step = 0;
  double wall_s = 0.0;
  double volts = 0.0;
  std::string note;
  bool applied() const { return note.empty() || note == "watchdog"; }
};
inline std::vector<LoggedCommand> read_command_log(const std::string& path) {
  std::vector<LoggedCommand> out;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    LoggedCommand c;
    if (std::sscanf(line.c_str(), "%lld,%lf,%lf", &c.step, &c.wall_s, &c.volts) == 3) {
      std::size_t at = 0;
      for (int commas = 0; commas < 3 && at != std::string::npos; ++commas) {
        at = line.find(',', at == 0 && commas == 0 ? 0 : at + 1);
      }
      if (at != std::string::npos) c.note = line.substr(at + 1);
      out.push_back(c);
    }
  }
  return out;
}

// The daemon's socket: one request, one reply (docs/protocol.md).
inline std::optional<nlohmann::json> request(const std::string& socket_path,
                                             const std::string& req) {
  const int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return std::nullopt;
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::snprintf(addr.sun_path, sizeof addr.sun_path, "%s", socket_path.c_str());
  if (connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    ::close(fd);
    return std::nullopt;
  }
  timeval tv{2, 0};
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  const std::string line = req + "\n";
  if (::write(fd, line.data(), line.size()) != static_cast<ssize_t>(line.size())) {
    ::close(fd);
    return std::nullopt;
  }
  std::string buf;
  char chunk[4096];
  std::optional<nlohmann::json> reply;
  while (!reply) {
    const ssize_t n = ::read(fd, chunk, sizeof chunk);
    if (n <= 0) break;
    buf.append(chunk, static_cast<std::size_t>(n));
    std::size_t nl;
    while (!reply && (nl = buf.find('\n')) != std::string::npos) {
      const auto j = nlohmann::json::parse(buf.substr(0, nl), nullptr, false);
      buf.erase(0, nl + 1);
      if (!j.is_discarded() && j.value("class", "") != "VERSION") reply = j;
    }
  }
  ::close(fd);
  return reply;
}

inline std::optional<nlohmann::json> status(const std::string& socket_path) {
  return request(socket_path, R"({"request":"status"})");
}

// Polls the daemon's status until pred holds (or timeout); returns the last status seen.
template <class Pred>
nlohmann::json wait_status(const std::string& socket_path, double timeout_s, Pred pred) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  nlohmann::json last;
  while (std::chrono::steady_clock::now() < end) {
    if (auto s = status(socket_path)) {
      last = *s;
      if (pred(last)) return last;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return last;
}

// CLOCK_REALTIME in ns, the clock of STATUS `last_fault.unix_ns`.
inline std::int64_t unix_now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// Waits for a FAULT that began at or after `since_unix_ns`. On a loaded machine a slow first
// reply or two can fault a tight Modbus link at start-up and it recovers by itself; waiting for
// any "fault" then finds that one instead of the one the test causes.
inline nlohmann::json wait_fault_since(const std::string& socket_path, std::int64_t since_unix_ns,
                                       double timeout_s) {
  return wait_status(socket_path, timeout_s, [&](const nlohmann::json& s) {
    return s.is_object() && s.value("state", "") == "fault" && s.contains("last_fault") &&
           s["last_fault"].value("unix_ns", std::int64_t{0}) >= since_unix_ns;
  });
}

// The last line of `scp-estimatord --offline` is one JSON object.
inline nlohmann::json last_json_line(const std::string& out) {
  std::istringstream in(out);
  std::string line;
  nlohmann::json last;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] != '{') continue;
    auto j = nlohmann::json::parse(line, nullptr, false);
    if (!j.is_discarded()) last = j;
  }
  return last;
}

}  // namespace scp::test

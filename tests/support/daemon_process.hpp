#pragma once
// Test harness for end-to-end tests: runs the real scp-estimatord binary as a child process with a
// temporary configuration, socket and state directory, talks to it over its socket like any
// client would, and always kills it (and removes the temporary files) when the test ends, pass or
// fail. Paths of the binaries come from compile definitions (see tests/support/CMakeLists.txt).

#include <sys/types.h>

#include <chrono>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace scp::test {

using nlohmann::json;
using Seconds = std::chrono::duration<double>;

std::string estimatord_path();
std::string estimatorctl_path();

// A fresh directory under /tmp (mode 0755 so an unprivileged peer can reach a socket in it),
// removed recursively on destruction.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::string& path() const noexcept { return path_; }
  std::string file(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

// Deep merge: maps are merged key by key, everything else in `over` replaces `base`.
json merge_config(json base, const json& over);
// The configuration every test daemon starts from: the simulated actuator at 1 kHz, ordinary
// scheduling, no memory locking, socket and state in `dir`, no socket group.
json base_config(const std::string& dir);
// Writes `config` as YAML (JSON is valid YAML flow style, one key per line for readable marks).
void write_config(const std::string& path, const json& config);
std::string read_text(const std::string& path);
void write_text(const std::string& path, const std::string& text);

// A line-oriented client of the daemon's socket. Every call has a timeout; none blocks forever.
class Client {
 public:
  // Connects and reads the VERSION line (throws std::runtime_error if either fails).
  explicit Client(const std::string& socket_path, bool read_version = true);
  ~Client();
  Client(Client&& other) noexcept
      : fd_(std::exchange(other.fd_, -1)), buffer_(std::move(other.buffer_)) {}
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  int fd() const noexcept { return fd_; }
  // False when the peer has gone (EPIPE, ECONNRESET).
  bool send_raw(const std::string& bytes);
  // The next line without its '\n'; nullopt on EOF, error or timeout (`timed_out` tells which).
  std::optional<std::string> read_line(Seconds timeout, bool* timed_out = nullptr);
  // The next object; throws on EOF/timeout/bad JSON.
  json read_json(Seconds timeout = Seconds(5));
  // Sends one request line and returns the next reply that is not an ESTIMATE of a watch stream
  // (unless the request itself was `estimate`).
  json request(const json& req, Seconds timeout = Seconds(5));

 private:
  int fd_ = -1;
  std::string buffer_;
};

struct ProcessResult {
  int exit_code = -1;  // -1: killed by a signal or timed out
  int signal = 0;
  std::string out;
  std::string err;
};

// Runs `argv` (argv[0] is the program path) with stdout/stderr captured; kills it after `timeout`.
ProcessResult run_process(const std::vector<std::string>& argv, Seconds timeout = Seconds(30));

struct DaemonOptions {
  std::vector<std::string> extra_env;   // "NAME=value", added to the child's environment
  std::vector<std::string> extra_args;  // after --config FILE (e.g. "--log-level", "debug")
  bool wait_ready = true;               // start() waits until the socket answers
  std::string binary;                   // another build of the daemon (e.g. -alloccount); "" = ours
};

class DaemonProcess {
 public:
  // `dir` holds the config, socket, state and logs; `overrides` are merged into base_config().
  DaemonProcess(const TempDir& dir, const json& overrides = json::object(),
                DaemonOptions options = {});
  ~DaemonProcess();  // SIGKILL + reap, whatever happened
  DaemonProcess(const DaemonProcess&) = delete;
  DaemonProcess& operator=(const DaemonProcess&) = delete;

  // Starts the binary (again, after it exited); waits for the socket unless told not to.
  void start();
  bool running();
  pid_t pid() const noexcept { return pid_; }
  void signal(int sig);
  // Exit code of the child once it exited (-1 if killed by a signal), nullopt on timeout.
  std::optional<int> wait_exit(Seconds timeout);
  // SIGKILL and reap, no questions asked.
  void kill_now();

  const std::string& socket_path() const noexcept { return socket_path_; }
  const std::string& config_path() const noexcept { return config_path_; }
  std::string state_dir() const { return state_dir_; }
  std::string state_file() const { return state_dir_ + "/estimator.state"; }
  std::string stderr_text() const;  // everything the daemon logged (all runs)
  // Polls stderr_text() until it contains `text` or timeout: the daemon logs from its own thread,
  // so a line about an event the socket already shows can still be on its way (under load, by
  // seconds). Returns whether it appeared.
  bool wait_logged(const std::string& text, Seconds timeout) const;
  const json& config() const noexcept { return config_; }

  Client connect() const { return Client(socket_path_); }
  // One request over a fresh connection.
  json request(const json& req) const;
  json status() const { return request({{"request", "status"}}); }
  json estimate() const { return request({{"request", "estimate"}}); }
  // scp-estimatorctl --socket <ours> args...; as_nobody runs it through setpriv as uid/gid 65534.
  ProcessResult run_ctl(const std::vector<std::string>& args, bool as_nobody = false) const;
  // Polls status until `pred` holds or timeout; returns the last status.
  template <class Pred>
  std::optional<json> wait_status(Pred pred, Seconds timeout) const;

 private:
  void wait_socket(Seconds timeout);

  json config_;
  DaemonOptions options_;
  std::string socket_path_;
  std::string config_path_;
  std::string state_dir_;
  std::string stderr_path_;
  pid_t pid_ = -1;
  int last_status_ = 0;  // raw wait status of the last exit
};

void sleep_s(double seconds);

template <class Pred>
std::optional<json> DaemonProcess::wait_status(Pred pred, Seconds timeout) const {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < end) {
    json s = status();
    if (pred(s)) return s;
    sleep_s(0.01);
  }
  return std::nullopt;
}

}  // namespace scp::test

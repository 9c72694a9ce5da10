#pragma once
// The client side of docs/protocol.md: connect, check the VERSION greeting, exchange JSON lines.
// Every wait has a timeout so that the tool never hangs on a stuck daemon.

#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>

namespace scp::daemon::ctl {

inline constexpr int kExitRefused = 1;      // the daemon answered ERROR or ACK ok:false
inline constexpr int kExitUnreachable = 2;  // no daemon, timeout, protocol mismatch
inline constexpr int kExitNotReached = 3;   // `wait`: the state was not reached in time

// Carries the process exit code with a message for the user.
class CtlError : public std::runtime_error {
 public:
  CtlError(int exit_code, const std::string& message)
      : std::runtime_error(message), exit_code_(exit_code) {}
  int exit_code() const noexcept { return exit_code_; }

 private:
  int exit_code_;
};

class Connection {
 public:
  // Connects and reads the VERSION object; throws CtlError(kExitUnreachable, ...) with a remedy.
  Connection(std::string path, double timeout_s);
  ~Connection();
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;

  const nlohmann::json& version() const noexcept { return version_; }

  void send(const nlohmann::json& request);
  // The next object from the daemon; throws CtlError on timeout, EOF or garbage.
  nlohmann::json read_object(double timeout_s);
  // Sends `request` and returns the first reply that is not part of a watch stream. An ERROR
  // reply is thrown as CtlError(kExitRefused, message).
  nlohmann::json exchange(const nlohmann::json& request);

 private:
  std::string read_line(double timeout_s);

  std::string path_;
  double timeout_s_;
  int fd_ = -1;
  std::string buffer_;
  nlohmann::json version_;
};

}  // namespace scp::daemon::ctl

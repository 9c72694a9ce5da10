#pragma once
// Test doubles for the socket server: a fake real-time loop that publishes a PublishedState and
// answers commands as the daemon's loop would, and a blocking line-oriented test client.

#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "daemon/core/published_state.hpp"
#include "daemon/core/rt/seqlock.hpp"
#include "daemon/outputs/server/api_server.hpp"

namespace scp::daemon::server::test {

using nlohmann::json;

// Table I of the paper: θ = [b/m, α1/m, k/m, α2/m, λ/Cth, 1/(R·Cth)].
inline constexpr std::array<double, 6> kThetaTrue{1247.0, 0.8, 1813.0, 0.1, 0.0594059, 1.1001100};

inline void copy_text(std::array<char, kReasonChars>& to, const char* text) {
  to.fill('\0');
  std::strncpy(to.data(), text, to.size() - 1);
}

// Publishes `base` every millisecond and applies commands like the daemon's loop.
class FakeLoop {
 public:
  FakeLoop(rt::Seqlock<PublishedState>& state, CommandRing& ring) : state_(state), ring_(ring) {}
  ~FakeLoop() { stop(); }

  void start() {
    state_.store(base);
    thread_ = std::thread([this] { run(); });
  }
  void stop() {
    running_ = false;
    if (thread_.joinable()) thread_.join();
  }
  std::vector<Command> received() {
    std::lock_guard<std::mutex> lock(mutex_);
    return received_;
  }

  PublishedState base{};  // set before start()
  std::atomic<bool> paused{false};
  std::atomic<bool> fault_persists{false};

 private:
  void run() {
    PublishedState s = base;
    while (running_) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
      if (paused) continue;
      Command command;
      while (ring_.try_pop(command)) {
        {
          std::lock_guard<std::mutex> lock(mutex_);
          received_.push_back(command);
        }
        s.last_ack.seq = command.seq;
        s.last_ack.ok = true;
        switch (command.kind) {
          case CommandKind::reset:
            s.estimate.updates = 0;
            copy_text(s.last_ack.message, "estimator reset");
            break;
          case CommandKind::excitation_on:
          case CommandKind::excitation_off:
            s.excitation_enabled = command.kind == CommandKind::excitation_on;
            copy_text(s.last_ack.message,
                      s.excitation_enabled ? "excitation enabled" : "excitation disabled");
            break;
          case CommandKind::clear_fault:
            if (fault_persists) {
              s.last_ack.ok = false;
              copy_text(s.last_ack.message, "fault persists: temperature sensor stale");
            } else {
              s.state = RunState::running;
              copy_text(s.last_ack.message, "fault cleared");
            }
            break;
        }
      }
      s.loop.cycles += 1;
      state_.store(s);
    }
  }

  rt::Seqlock<PublishedState>& state_;
  CommandRing& ring_;
  std::thread thread_;
  std::atomic<bool> running_{true};
  std::mutex mutex_;
  std::vector<Command> received_;
};

// A blocking client that reads one JSON object per line, with timeouts.
class TestClient {
 public:
  explicit TestClient(const std::string& path, int rcvbuf = 0) {
    fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (rcvbuf > 0) ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof(rcvbuf));
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::strncpy(addr.sun_path, path.c_str(), sizeof(addr.sun_path) - 1);
    connected_ = ::connect(fd_, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)) == 0;
  }
  ~TestClient() {
    if (fd_ >= 0) ::close(fd_);
  }
  TestClient(const TestClient&) = delete;
  TestClient& operator=(const TestClient&) = delete;

  bool connected() const { return connected_; }
  int fd() const { return fd_; }

  bool send_raw(const std::string& bytes) {
    std::size_t sent = 0;
    while (sent < bytes.size()) {
      const ssize_t n = ::send(fd_, bytes.data() + sent, bytes.size() - sent, MSG_NOSIGNAL);
      if (n <= 0) return false;
      sent += static_cast<std::size_t>(n);
    }
    return true;
  }
  bool send(const json& request) { return send_raw(request.dump() + "\n"); }

  // The next line, or nullopt on timeout / EOF (then closed() tells which).
  std::optional<std::string> read_line(double timeout_s = 3.0) {
    const auto deadline = std::chrono::steady_clock::now() +
                          std::chrono::microseconds(static_cast<long>(timeout_s * 1e6));
    for (;;) {
      const auto nl = buffer_.find('\n');
      if (nl != std::string::npos) {
        std::string line = buffer_.substr(0, nl);
        buffer_.erase(0, nl + 1);
        return line;
      }
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
                            deadline - std::chrono::steady_clock::now())
                            .count();
      if (left <= 0 || closed_) return std::nullopt;
      pollfd pfd{fd_, POLLIN, 0};
      if (::poll(&pfd, 1, static_cast<int>(left)) <= 0) continue;
      char chunk[65536];
      const ssize_t n = ::recv(fd_, chunk, sizeof(chunk), 0);
      if (n <= 0) {
        closed_ = true;  // EOF or ECONNRESET (the server closed with our data unread)
        continue;
      }
      buffer_.append(chunk, static_cast<std::size_t>(n));
    }
  }
  std::optional<json> read_json(double timeout_s = 3.0) {
    auto line = read_line(timeout_s);
    if (!line) return std::nullopt;
    return json::parse(*line);
  }
  // The next object whose class is `cls`, skipping others (e.g. a watch stream).
  std::optional<json> read_class(const std::string& cls, double timeout_s = 3.0) {
    const auto deadline = std::chrono::steady_clock::now() +
                          std::chrono::microseconds(static_cast<long>(timeout_s * 1e6));
    while (std::chrono::steady_clock::now() < deadline) {
      auto object = read_json(
          std::chrono::duration<double>(deadline - std::chrono::steady_clock::now()).count());
      if (!object) return std::nullopt;
      if (object->value("class", "") == cls) return object;
    }
    return std::nullopt;
  }
  // True when the server closed the connection within the timeout (data before EOF is dropped).
  bool wait_closed(double timeout_s) {
    const auto deadline = std::chrono::steady_clock::now() +
                          std::chrono::microseconds(static_cast<long>(timeout_s * 1e6));
    while (!closed_ && std::chrono::steady_clock::now() < deadline) {
      buffer_.clear();
      read_line(0.05);
    }
    return closed_;
  }

 private:
  int fd_ = -1;
  bool connected_ = false;
  bool closed_ = false;
  std::string buffer_;
};

// A private directory for the socket, world-traversable so that a child running as `nobody` can
// reach the socket.
class TempDir {
 public:
  TempDir() {
    char pattern[] = "/tmp/scp-srv-test-XXXXXX";
    path_ = ::mkdtemp(pattern);
    ::chmod(path_.c_str(), 0755);
  }
  ~TempDir() { std::system(("rm -rf '" + path_ + "'").c_str()); }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

// A PublishedState with distinctive values the tests compare against.
inline PublishedState sample_state() {
  PublishedState s;
  s.state = RunState::running;
  s.uptime_s = 12.5;
  s.period_s = 0.001;
  s.excitation_enabled = true;
  s.voltage_command = 1.75;
  s.last_sample = {12.5, 1.25e-3, drivers::kNotMeasured, 31.5, 1.75};
  s.loop.cycles = 12500;
  s.loop.overruns = 3;
  s.loop.missed_periods = 4;
  s.loop.lateness_min_us = 1.5;
  s.loop.lateness_mean_us = 7.25;
  s.loop.lateness_p99_us = 32.0;
  s.loop.lateness_max_us = 80.5;
  s.loop.exec_mean_us = 3.5;
  s.loop.exec_max_us = 20.25;
  for (std::size_t i = 0; i < kHistogramBins; ++i) s.loop.lateness_histogram[i] = 100 + i;
  s.driver = {12500, 1, 12499, 2, 5, 6, true};
  EstimateView& e = s.estimate;
  e.t = 12.5;
  // θ̂ᵢ = θᵢ (1 + 0.01 (i+1)), so the relative errors are 0.01, 0.02, ..., 0.06.
  for (std::size_t i = 0; i < 6; ++i) {
    e.theta_hat[i] = kThetaTrue[i] * (1.0 + 0.01 * static_cast<double>(i + 1));
    e.sigma[i] = 0.5 * static_cast<double>(i + 1);
  }
  e.sigma[2] = std::numeric_limits<double>::infinity();  // not yet known → null on the wire
  e.eps = {1e-9, -2e-7};
  e.af = {0.01, 0.3};
  e.af_hat = {0.011, 0.31};
  e.excitation = {0.25, 0.75};
  e.p_max_eig = {4.0e6, 12.5};
  e.converged = {false, true};
  e.updates = 12500;
  e.skipped = 7;
  e.has_truth = true;
  e.theta_true = kThetaTrue;
  e.has_physical = true;
  e.physical = {124.7, 181.3, 0.08, 0.01, 0.054, 0.909};
  return s;
}

}  // namespace scp::daemon::server::test

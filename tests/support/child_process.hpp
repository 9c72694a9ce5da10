#pragma once
// A program a test starts (the daemon, scp-simdaq, socat, mbpoll, a pymodbus server) with stdout
// and stderr on one pipe, killed by pid (never by name) when the test ends, even on failure.
// `inherit_fd` ≥ 0 is passed to it as fd 3 (the CAN tests' socket pair).

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <string>
#include <vector>

namespace scp::test {

class ChildProcess {
 public:
  explicit ChildProcess(const std::vector<std::string>& argv, int inherit_fd = -1) {
    int fds[2];
    if (pipe2(fds, O_CLOEXEC) != 0) return;
    pid_ = fork();
    if (pid_ == 0) {
      dup2(fds[1], 1);
      dup2(fds[1], 2);
      if (inherit_fd >= 0) {
        if (inherit_fd == 3) {
          fcntl(3, F_SETFD, 0);
        } else {
          dup2(inherit_fd, 3);  // dup2 clears FD_CLOEXEC on the copy
        }
      }
      std::vector<char*> args;
      for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
      args.push_back(nullptr);
      execv(args[0], args.data());
      _exit(127);
    }
    ::close(fds[1]);
    out_ = fds[0];
    fcntl(out_, F_SETFL, O_NONBLOCK);
  }
  ~ChildProcess() {
    stop(SIGKILL);
    if (out_ >= 0) ::close(out_);
  }
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  pid_t pid() const { return pid_; }
  bool running() {
    if (pid_ <= 0) return false;
    int status = 0;
    if (waitpid(pid_, &status, WNOHANG) == pid_) {
      pid_ = -1;
      status_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      return false;
    }
    return true;
  }

  // Output so far plus what arrives until `pattern` appears or the timeout passes.
  bool wait_for(const std::string& pattern, double timeout_s) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    while (output_.find(pattern) == std::string::npos) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          end - std::chrono::steady_clock::now());
      if (left.count() <= 0) return false;
      pollfd p{out_, POLLIN, 0};
      if (poll(&p, 1, static_cast<int>(std::min<long long>(left.count(), 100))) <= 0) continue;
      if (!drain()) return output_.find(pattern) != std::string::npos;
    }
    return true;
  }
  const std::string& output() {
    drain();
    return output_;
  }
  // Waits for the exit (up to timeout_s); returns the exit status or -1 on timeout.
  int wait_exit(double timeout_s) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    while (std::chrono::steady_clock::now() < end) {
      drain();
      if (!running()) {
        drain();
        return status_;
      }
      usleep(5000);
    }
    return -1;
  }
  void stop(int sig) {
    if (pid_ <= 0) return;
    kill(pid_, sig);
    int status = 0;
    waitpid(pid_, &status, 0);
    status_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    pid_ = -1;
    drain();
  }

 private:
  bool drain() {
    char buf[4096];
    for (;;) {
      const ssize_t n = ::read(out_, buf, sizeof buf);
      if (n > 0) {
        output_.append(buf, static_cast<std::size_t>(n));
        continue;
      }
      return n < 0;  // 0 = EOF
    }
  }
  pid_t pid_ = -1;
  int out_ = -1;
  int status_ = -1;
  std::string output_;
};

inline bool executable(const std::string& path) {
  return access(path.c_str(), X_OK) == 0;
}

}  // namespace scp::test

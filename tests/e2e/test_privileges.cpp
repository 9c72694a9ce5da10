// Issue 3: monitoring is open to anyone who can connect, control is not.

#include <grp.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstring>

#include "tests/e2e/e2e_util.hpp"

namespace scp::test {
namespace {

constexpr uid_t kNobody = 65534;

// In a forked child that has dropped to uid/gid 65534: connect, ask for an estimate, then try a
// reset; the replies come back through a pipe. Uses raw syscalls only (we are after fork()).
std::string exchange_as_nobody(const std::string& socket_path) {
  int pipe_fds[2];
  if (::pipe(pipe_fds) != 0) return "pipe failed";
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::close(pipe_fds[0]);
    const int out = pipe_fds[1];
    auto fail = [out](const char* what) {
      (void)!::write(out, what, std::strlen(what));
      ::_exit(1);
    };
    if (::setgroups(0, nullptr) != 0 || ::setgid(kNobody) != 0 || ::setuid(kNobody) != 0) {
      fail("cannot drop privileges");
    }
    const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::snprintf(addr.sun_path, sizeof addr.sun_path, "%s", socket_path.c_str());
    if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) fail("connect failed");
    const char requests[] = "{\"request\":\"estimate\"}\n{\"request\":\"reset\"}\n";
    (void)!::write(fd, requests, sizeof requests - 1);
    ::shutdown(fd, SHUT_WR);  // the server answers everything, then closes
    char buffer[65536];
    ssize_t n;
    while ((n = ::read(fd, buffer, sizeof buffer)) > 0)
      (void)!::write(out, buffer, static_cast<std::size_t>(n));
    ::_exit(0);
  }
  ::close(pipe_fds[1]);
  std::string text;
  char buffer[65536];
  ssize_t n;
  while ((n = ::read(pipe_fds[0], buffer, sizeof buffer)) > 0)
    text.append(buffer, static_cast<std::size_t>(n));
  ::close(pipe_fds[0]);
  int status = 0;
  ::waitpid(pid, &status, 0);
  return text;
}

// A user outside the daemon's group (here: nobody) can read the estimate, but a `reset` is
// answered "permission denied" and the estimator keeps its learned state. If the privilege
// check were missing, the ACK would say ok and `updates` would drop back to ~0.
TEST(Privileges, UnprivilegedPeerMayReadButNotReset) {
  TempDir dir;
  DaemonProcess daemon(dir, {{"socket", {{"mode", "0666"}}}});
  daemon.start();
  sleep_s(1.0);
  const auto updates_before = daemon.estimate().value("updates", 0ULL);
  ASSERT_GT(updates_before, 500u);

  const std::string text = exchange_as_nobody(daemon.socket_path());
  std::vector<json> replies;
  std::size_t start = 0;
  for (std::size_t nl; (nl = text.find('\n', start)) != std::string::npos; start = nl + 1) {
    replies.push_back(json::parse(text.substr(start, nl - start)));
  }
  ASSERT_EQ(replies.size(), 3u) << "expected VERSION, ESTIMATE, ERROR; got:\n" << text;
  EXPECT_EQ(replies[1].value("class", ""), "ESTIMATE") << text;
  EXPECT_EQ(replies[2].value("class", ""), "ERROR") << text;
  EXPECT_TRUE(contains(replies[2].value("message", ""), "permission denied")) << text;

  // Through the client, as nobody: `get` works (exit 0), `reset` is refused (exit 1, message).
  const ProcessResult get = daemon.run_ctl({"get"}, /*as_nobody=*/true);
  EXPECT_EQ(get.exit_code, 0) << get.out << get.err;
  const ProcessResult reset = daemon.run_ctl({"reset"}, /*as_nobody=*/true);
  EXPECT_EQ(reset.exit_code, 1) << reset.out << reset.err;
  EXPECT_TRUE(contains(reset.out + reset.err, "permission denied")) << reset.out << reset.err;
  const ProcessResult off = daemon.run_ctl({"excitation", "off"}, /*as_nobody=*/true);
  EXPECT_EQ(off.exit_code, 1) << off.out << off.err;

  // Nothing was reset and the output kept running.
  const json after = daemon.estimate();
  EXPECT_GT(after.value("updates", 0ULL), updates_before) << after.dump();
  EXPECT_TRUE(daemon.status().value("excitation", false));
  // Root (the daemon's own uid) may.
  const ProcessResult root_reset = daemon.run_ctl({"reset"});
  EXPECT_EQ(root_reset.exit_code, 0) << root_reset.out << root_reset.err;
}

}  // namespace
}  // namespace scp::test

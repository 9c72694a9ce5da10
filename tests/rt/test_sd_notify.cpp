#include <gtest/gtest.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <sys/un.h>
#include <unistd.h>

#include <cstdlib>
#include <cstring>
#include <string>

#include "daemon/core/rt/alloc_counter.hpp"
#include "daemon/core/rt/sd_notify.hpp"

namespace scp::rt {
namespace {

using namespace std::chrono_literals;

// Plays systemd: a datagram socket bound to a filesystem path or an abstract name, with
// SO_PASSCRED so the sender's pid can be checked as systemd's NotifyAccess= does.
class FakeSystemd {
 public:
  explicit FakeSystemd(bool abstract) {
    fd_ = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    EXPECT_GE(fd_, 0);
    const int one = 1;
    setsockopt(fd_, SOL_SOCKET, SO_PASSCRED, &one, sizeof(one));
    timeval tv{2, 0};  // a lost datagram fails the test instead of hanging it
    setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
    const std::string name =
        "scp-notify-test-" + std::to_string(getpid()) + (abstract ? "-a" : "-p");
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    socklen_t len;
    if (abstract) {
      env_ = "@" + name;
      std::memcpy(addr.sun_path + 1, name.data(), name.size());
      len = static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + 1 + name.size());
    } else {
      path_ = (std::getenv("TMPDIR") ? std::string(std::getenv("TMPDIR")) : std::string("/tmp")) +
              "/" + name;
      ::unlink(path_.c_str());
      env_ = path_;
      std::memcpy(addr.sun_path, path_.data(), path_.size());
      len = static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + path_.size() + 1);
    }
    EXPECT_EQ(bind(fd_, reinterpret_cast<sockaddr*>(&addr), len), 0) << std::strerror(errno);
  }
  ~FakeSystemd() {
    close(fd_);
    if (!path_.empty()) ::unlink(path_.c_str());
  }
  const std::string& env() const { return env_; }

  // Next datagram as text ("<timeout>" if none), and the sender's pid.
  std::string receive(pid_t* sender = nullptr) {
    char data[512];
    alignas(cmsghdr) char control[CMSG_SPACE(sizeof(ucred))];
    iovec iov{data, sizeof(data)};
    msghdr msg{};
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    msg.msg_control = control;
    msg.msg_controllen = sizeof(control);
    const ssize_t n = recvmsg(fd_, &msg, 0);
    if (n < 0) return "<timeout>";
    for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c != nullptr; c = CMSG_NXTHDR(&msg, c)) {
      if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SCM_CREDENTIALS && sender != nullptr) {
        ucred cred{};
        std::memcpy(&cred, CMSG_DATA(c), sizeof(cred));
        *sender = cred.pid;
      }
    }
    return std::string(data, static_cast<std::size_t>(n));
  }

 private:
  int fd_ = -1;
  std::string path_;
  std::string env_;
};

class ScopedEnv {
 public:
  ScopedEnv(const char* notify, const char* usec, const char* pid) {
    set("NOTIFY_SOCKET", notify);
    set("WATCHDOG_USEC", usec);
    set("WATCHDOG_PID", pid);
  }
  ~ScopedEnv() {
    unsetenv("NOTIFY_SOCKET");
    unsetenv("WATCHDOG_USEC");
    unsetenv("WATCHDOG_PID");
  }

 private:
  static void set(const char* key, const char* value) {
    if (value)
      setenv(key, value, 1);
    else
      unsetenv(key);
  }
};

void exercise_protocol(bool abstract) {
  FakeSystemd systemd(abstract);
  const std::string pid = std::to_string(getpid());
  const ScopedEnv env(systemd.env().c_str(), "2000000", pid.c_str());
  ServiceNotifier n = ServiceNotifier::from_environment();
  ASSERT_TRUE(n.enabled()) << n.problem();
  EXPECT_TRUE(n.problem().empty()) << n.problem();
  EXPECT_EQ(n.watchdog_interval(), 2s);

  EXPECT_TRUE(n.ready());
  pid_t sender = 0;
  EXPECT_EQ(systemd.receive(&sender), "READY=1");
  EXPECT_EQ(sender, getpid());

  EXPECT_TRUE(n.status("estimating\nθ converged"));
  EXPECT_EQ(systemd.receive(), "STATUS=estimating θ converged");

  alloc::arm();
  const alloc::ScopedAllocationCount count;
  bool sent = true;
  for (int i = 0; i < 3; ++i) sent = n.watchdog() && sent;
  EXPECT_EQ(count.count(), 0U);
  alloc::disarm();
  EXPECT_TRUE(sent);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(systemd.receive(), "WATCHDOG=1");

  EXPECT_TRUE(n.stopping());
  EXPECT_EQ(systemd.receive(), "STOPPING=1");

  // A move keeps the socket; the moved-from notifier is disabled.
  ServiceNotifier moved = std::move(n);
  EXPECT_TRUE(moved.enabled());
  EXPECT_TRUE(moved.watchdog_trigger());
  EXPECT_EQ(systemd.receive(), "WATCHDOG=trigger");
}

TEST(ServiceNotifier, FilesystemSocket) {
  exercise_protocol(false);
}
TEST(ServiceNotifier, AbstractSocket) {
  exercise_protocol(true);
}

TEST(ServiceNotifier, DisabledWithoutNotifySocket) {
  const ScopedEnv env(nullptr, "1000000", nullptr);
  ServiceNotifier n = ServiceNotifier::from_environment();
  EXPECT_FALSE(n.enabled());
  EXPECT_TRUE(n.problem().empty());
  EXPECT_FALSE(n.ready());
  EXPECT_FALSE(n.watchdog());
  EXPECT_FALSE(n.status("x"));
  EXPECT_FALSE(n.stopping());
}

TEST(ServiceNotifier, WatchdogOfAnotherProcessIsNotPetted) {
  FakeSystemd systemd(true);
  const ServiceNotifier other =
      ServiceNotifier::from_values(systemd.env().c_str(), "500000", "1", 4242);
  ServiceNotifier n = ServiceNotifier::from_values(systemd.env().c_str(), "500000", "1", 4242);
  EXPECT_TRUE(n.enabled());  // READY=1 still goes out
  EXPECT_EQ(n.watchdog_interval().count(), 0);
  EXPECT_NE(n.problem().find("WATCHDOG_PID=1"), std::string::npos) << n.problem();
  EXPECT_FALSE(n.watchdog());
  EXPECT_EQ(other.watchdog_interval().count(), 0);
}

TEST(ServiceNotifier, WatchdogWithoutPidIsOurs) {
  FakeSystemd systemd(true);
  const ServiceNotifier n =
      ServiceNotifier::from_values(systemd.env().c_str(), "500000", nullptr, 4242);
  EXPECT_EQ(n.watchdog_interval(), 500ms);
}

TEST(ServiceNotifier, BadValuesAreExplained) {
  const ServiceNotifier vsock = ServiceNotifier::from_values("vsock:2:1234", nullptr, nullptr, 1);
  EXPECT_FALSE(vsock.enabled());
  EXPECT_NE(vsock.problem().find("NOTIFY_SOCKET=vsock:2:1234"), std::string::npos)
      << vsock.problem();

  const std::string too_long = "/" + std::string(200, 'x');
  EXPECT_FALSE(ServiceNotifier::from_values(too_long.c_str(), nullptr, nullptr, 1).enabled());

  FakeSystemd systemd(true);
  for (const char* bad : {"abc", "-5", "0", "12x", ""}) {
    const ServiceNotifier n = ServiceNotifier::from_values(systemd.env().c_str(), bad, nullptr, 1);
    EXPECT_EQ(n.watchdog_interval().count(), 0) << bad;
    EXPECT_NE(n.problem().find("WATCHDOG_USEC"), std::string::npos) << bad;
  }
}

TEST(ServiceNotifier, SendToAVanishedSocketFailsWithoutBlocking) {
  std::string env;
  {
    FakeSystemd systemd(false);
    env = systemd.env();
  }  // socket closed and unlinked
  ServiceNotifier n = ServiceNotifier::from_values(env.c_str(), "1000000", nullptr, 1);
  ASSERT_TRUE(n.enabled());
  EXPECT_FALSE(n.watchdog());
  EXPECT_FALSE(n.ready());
}

TEST(WatchdogPacer, PingsEveryHalfInterval) {
  WatchdogPacer pacer(2s, 1ms);  // half of 2 s at 1 kHz: every 1000 cycles
  EXPECT_EQ(pacer.cycles_per_ping(), 1000U);
  EXPECT_TRUE(pacer.due(0));
  for (std::uint64_t k = 1; k < 1000; ++k) ASSERT_FALSE(pacer.due(k)) << k;
  EXPECT_TRUE(pacer.due(1000));
  // Skipped periods count: a jump of the cycle index is elapsed time.
  EXPECT_TRUE(pacer.due(2500));
  EXPECT_FALSE(pacer.due(3499));
  EXPECT_TRUE(pacer.due(3500));
}

TEST(WatchdogPacer, PingCountOverTenSeconds) {
  // 10 s of a 1 kHz loop with a 2 s watchdog: a ping at t = 0, 1, ..., 10 s → 11 pings, and no
  // gap between pings longer than half the interval.
  WatchdogPacer pacer(2s, 1ms);
  int pings = 0;
  std::uint64_t last = 0;
  std::uint64_t longest_gap = 0;
  for (std::uint64_t k = 0; k <= 10'000; ++k) {
    if (pacer.due(k)) {
      ++pings;
      longest_gap = std::max(longest_gap, k - last);
      last = k;
    }
  }
  EXPECT_EQ(pings, 11);
  EXPECT_LE(longest_gap, 1000U);
}

TEST(WatchdogPacer, DisabledAndSlowLoops) {
  WatchdogPacer off;
  EXPECT_FALSE(off.due(0));
  WatchdogPacer zero(0us, 1ms);
  EXPECT_FALSE(zero.due(0));
  WatchdogPacer slow(1s, 2s);  // period longer than half the interval: every cycle
  EXPECT_TRUE(slow.due(0));
  EXPECT_TRUE(slow.due(1));
  EXPECT_TRUE(slow.due(2));
}

}  // namespace
}  // namespace scp::rt

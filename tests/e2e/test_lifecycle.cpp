// Issues 3 and 5: stopping, restarting and being supervised, as systemd and an operator see it.

#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <chrono>
#include <random>

#include "tests/e2e/e2e_util.hpp"

namespace scp::test {
namespace {

using Clock = std::chrono::steady_clock;

// SIGTERM (systemctl stop): exit code 0 and the checkpoint written. The next start resumes from
// it ("warm start" in the journal, θ̂ where it was). A corrupt checkpoint gives a warning and a
// cold start, never a refusal to run.
TEST(Lifecycle, SigtermCheckpointWarmStartAndCorruptState) {
  TempDir dir;
  DaemonProcess daemon(dir);
  daemon.start();
  sleep_s(3.0);
  ASSERT_FALSE(std::filesystem::exists(daemon.state_file())) << "checkpoint interval is 60 s";
  daemon.signal(SIGTERM);
  const auto code = daemon.wait_exit(Seconds(10));
  ASSERT_TRUE(code) << "did not stop within 10 s of SIGTERM";
  EXPECT_EQ(*code, 0) << daemon.stderr_text();
  ASSERT_TRUE(std::filesystem::exists(daemon.state_file())) << daemon.stderr_text();
  const json saved = json::parse(read_text(daemon.state_file()));
  const auto saved_theta = saved.at("theta_hat").get<std::vector<double>>();
  // After 3 s of excitation the thermal pair has clearly left θ0 = 0.
  ASSERT_GT(saved_theta[5], 0.1 * theta_true()[5]) << saved.dump();

  daemon.start();
  const json resumed = daemon.estimate();
  EXPECT_TRUE(contains(daemon.stderr_text(), "warm start")) << daemon.stderr_text();
  for (std::size_t i : {4u, 5u}) {
    EXPECT_NEAR(resumed["theta_hat"][i].get<double>(), saved_theta[i],
                0.05 * std::fabs(saved_theta[i]))
        << "theta_hat[" << i << "] did not resume from the checkpoint: " << resumed.dump();
  }
  daemon.signal(SIGTERM);
  ASSERT_EQ(daemon.wait_exit(Seconds(10)), std::optional<int>(0));

  // Corrupt: flip the checkpoint into garbage. The daemon warns, starts cold, and runs.
  std::string text = read_text(daemon.state_file());
  text[text.size() / 2] = text[text.size() / 2] == '1' ? '2' : '1';
  write_text(daemon.state_file(), text);
  const auto log_before = daemon.stderr_text().size();
  daemon.start();
  sleep_s(0.3);
  const std::string log = daemon.stderr_text().substr(log_before);
  EXPECT_TRUE(contains(log, "warn")) << log;
  EXPECT_TRUE(contains(log, "starting cold")) << log;
  EXPECT_FALSE(contains(log, "warm start from")) << log;
  const json st = daemon.status();
  EXPECT_EQ(st.value("state", ""), "running") << st.dump();
  EXPECT_TRUE(daemon.running());
}

// A fake service manager: the datagram socket systemd would pass in $NOTIFY_SOCKET.
class NotifySocket {
 public:
  explicit NotifySocket(const std::string& path) : path_(path) {
    fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::snprintf(addr.sun_path, sizeof addr.sun_path, "%s", path.c_str());
    if (::bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
      throw std::runtime_error("cannot bind " + path);
    }
  }
  ~NotifySocket() { ::close(fd_); }
  struct Message {
    double at_s;  // seconds since construction
    std::string text;
  };
  // Collects datagrams for `seconds`.
  void collect(double seconds) {
    const auto end = Clock::now() + Seconds(seconds);
    while (Clock::now() < end) {
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, 10) <= 0) continue;
      char buffer[4096];
      const ssize_t n = ::recv(fd_, buffer, sizeof buffer, MSG_DONTWAIT);
      if (n <= 0) continue;
      messages.push_back({Seconds(Clock::now() - start_).count(),
                          std::string(buffer, static_cast<std::size_t>(n))});
    }
  }
  double now_s() const { return Seconds(Clock::now() - start_).count(); }
  std::vector<Message> messages;

 private:
  std::string path_;
  int fd_ = -1;
  Clock::time_point start_ = Clock::now();
};

// systemd's view (Type=notify, WatchdogSec): READY=1 once running, WATCHDOG=1 about every half
// interval, silence while the driver call hangs (so systemd would restart a wedged daemon), pings
// again once it returns, STOPPING=1 on SIGTERM. Without these, systemd would kill a healthy
// daemon or keep a hung one.
TEST(Lifecycle, ServiceManagerNotifications) {
  TempDir dir;
  NotifySocket notify(dir.file("notify.sock"));
  DaemonOptions options;
  options.extra_env = {"NOTIFY_SOCKET=" + dir.file("notify.sock"), "WATCHDOG_USEC=400000"};
  DaemonProcess daemon(
      dir,
      {{"driver",
        {{"sim", {{"fault", {{"kind", "stall"}, {"start_s", 3.0}, {"duration_s", 2.0}}}}}}}},
      options);
  daemon.start();
  notify.collect(6.5);
  const double sigterm_at = notify.now_s();
  daemon.signal(SIGTERM);
  notify.collect(1.0);
  EXPECT_EQ(daemon.wait_exit(Seconds(10)), std::optional<int>(0)) << daemon.stderr_text();

  std::vector<double> pings;
  double ready_at = -1, stopping_at = -1;
  for (const auto& m : notify.messages) {
    if (contains(m.text, "READY=1") && ready_at < 0) ready_at = m.at_s;
    if (contains(m.text, "STOPPING=1")) stopping_at = m.at_s;
    if (contains(m.text, "WATCHDOG=1")) pings.push_back(m.at_s);
  }
  ASSERT_GE(ready_at, 0.0) << "no READY=1";
  EXPECT_GE(stopping_at, sigterm_at) << "no STOPPING=1 after SIGTERM";
  ASSERT_GE(pings.size(), 10u);
  // The stall: exactly one silence of ≈ 2 s; every other gap well inside the 0.4 s interval.
  int long_gaps = 0;
  double stall_gap = 0.0, stall_end = 0.0;
  for (std::size_t i = 1; i < pings.size(); ++i) {
    const double gap = pings[i] - pings[i - 1];
    if (gap > 1.0) {
      ++long_gaps;
      stall_gap = gap;
      stall_end = pings[i];
    } else {
      EXPECT_LT(gap, 0.4) << "watchdog would expire at " << pings[i - 1] << " s";
    }
  }
  EXPECT_EQ(long_gaps, 1) << "expected one silence during the stall";
  EXPECT_GT(stall_gap, 1.8);
  EXPECT_LT(stall_gap, 4.0);
  int after = 0;
  for (double p : pings) after += p > stall_end && p < sigterm_at;
  EXPECT_GE(after, 3) << "pings did not resume after the stall";
}

// Issue 5: kill -9 while checkpoints are written every 0.1 s, many times. Each next start must
// find a complete checkpoint (warm start), never a torn one: the write is atomic (tmp + rename).
TEST(Lifecycle, SigkillDuringCheckpointsNeverLeavesACorruptState) {
  TempDir dir;
  DaemonProcess daemon(dir, {{"state", {{"checkpoint_interval_s", 0.1}}}});
  daemon.start();
  const auto deadline = Clock::now() + Seconds(10);
  while (!std::filesystem::exists(daemon.state_file()) && Clock::now() < deadline) sleep_s(0.05);
  ASSERT_TRUE(std::filesystem::exists(daemon.state_file())) << daemon.stderr_text();
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> delay(0.05, 0.45);
  constexpr int kRuns = 12;
  for (int run = 0; run < kRuns; ++run) {
    sleep_s(delay(rng));
    daemon.kill_now();
    const auto log_before = daemon.stderr_text().size();
    daemon.start();
    const std::string log = daemon.stderr_text().substr(log_before);
    EXPECT_TRUE(contains(log, "warm start from")) << "run " << run << ":\n" << log;
    EXPECT_FALSE(contains(log, "ignoring checkpoint")) << "run " << run << ":\n" << log;
    EXPECT_FALSE(contains(log, "unusable")) << "run " << run << ":\n" << log;
  }
  // Temporaries of killed processes do not pile up.
  int temporaries = 0;
  for (const auto& entry : std::filesystem::directory_iterator(daemon.state_dir())) {
    temporaries += contains(entry.path().filename().string(), ".tmp.");
  }
  EXPECT_LE(temporaries, 2);
}

}  // namespace
}  // namespace scp::test

// Issue 9, part 4: a hostile local user. Every attack the issue measured, replayed against the
// real daemon: slots held by watchers, a symlink or FIFO where the checkpoint goes, a poisoned
// checkpoint, configuration files that are no files, an empty socket mode, NUL in a request.

#include <grp.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <cstring>
#include <vector>

#include "daemon/service/state/checkpoint.hpp"
#include "tests/e2e/e2e_util.hpp"

namespace scp::test {
namespace {

constexpr uid_t kNobody = 65534;

// A forked child, dropped to uid/gid 65534, that opens `n` watch streams at 0.1 Hz and holds them
// until killed. It reports how many got their VERSION greeting through the pipe, one byte each.
struct Watchers {
  pid_t pid = -1;
  int greeted = 0;
  Watchers(const std::string& socket_path, int n) {
    int fds[2];
    if (::pipe(fds) != 0) return;
    pid = ::fork();
    if (pid == 0) {
      ::close(fds[0]);
      if (::setgroups(0, nullptr) != 0 || ::setgid(kNobody) != 0 || ::setuid(kNobody) != 0)
        ::_exit(1);
      for (int i = 0; i < n; ++i) {
        const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
        sockaddr_un addr{};
        addr.sun_family = AF_UNIX;
        std::snprintf(addr.sun_path, sizeof addr.sun_path, "%s", socket_path.c_str());
        if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) continue;
        const char watch[] = "{\"request\":\"watch\",\"rate_hz\":0.1}\n";
        (void)!::write(fd, watch, sizeof watch - 1);
        char buffer[256];
        const ssize_t got = ::read(fd, buffer, sizeof buffer);
        if (got > 0 && ::memmem(buffer, static_cast<std::size_t>(got), "VERSION", 7)) {
          (void)!::write(fds[1], "v", 1);
        }
      }
      ::close(fds[1]);
      for (;;) ::pause();
    }
    ::close(fds[1]);
    char c;
    while (::read(fds[0], &c, 1) == 1) {
      if (++greeted == n) break;
    }
    ::close(fds[0]);
  }
  ~Watchers() {
    if (pid > 0) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, nullptr, 0);
    }
  }
};

// Unprivileged watchers hold every ordinary slot; root's `excitation off` must still be
// answered (slots reserved for privileged peers), the refusal of one more watcher is logged with
// its uid, and scp-estimatorctl run as that user shows the server's "too many clients".
TEST(Hostile, WatchersHoldingEverySlotCannotLockRootOut) {
  TempDir dir;
  DaemonProcess daemon(dir, {{"socket", {{"mode", "0666"}, {"max_clients", 8}}}});
  daemon.start();
  Watchers watchers(daemon.socket_path(), 8);
  ASSERT_EQ(watchers.greeted, 8);
  const ProcessResult nobody = daemon.run_ctl({"status"}, true);
  EXPECT_NE(nobody.exit_code, 0);
  EXPECT_TRUE(contains(nobody.err + nobody.out, "too many clients")) << nobody.err << nobody.out;
  const ProcessResult off = daemon.run_ctl({"excitation", "off"});
  EXPECT_EQ(off.exit_code, 0) << off.out << off.err;
  const json st = daemon.status();
  EXPECT_EQ(st.value("excitation", true), false) << st.dump();
  sleep_s(0.2);
  const std::string log = daemon.stderr_text();
  EXPECT_TRUE(contains(log, "client uid 65534 pid")) << log;
  EXPECT_TRUE(contains(log, "too many clients")) << log;
}

// 125 watchers at 1 kHz that never read used to raise the daemon's RSS from 50 to 176 MB (1 MiB
// of output each). The output budget (docs/protocol.md) bounds it.
TEST(Hostile, NonReadingWatchersCannotGrowTheDaemonBeyondTheBudget) {
#if defined(__SANITIZE_ADDRESS__)
  // ASan keeps freed blocks in its quarantine (256 MiB by default) and pads every allocation, so
  // the daemon's peak RSS says nothing about the output budget there; the normal build checks it.
  GTEST_SKIP() << "RSS budgets are not measurable under AddressSanitizer";
#endif
  TempDir dir;
  DaemonProcess daemon(dir);
  daemon.start();
  sleep_s(0.5);
  // The peak, not the current value: a buffer freed at the drop may already be back with the
  // system, but memory it held at its peak was needed.
  const auto rss_kib = [&] {
    const std::string text = read_text("/proc/" + std::to_string(daemon.pid()) + "/status");
    const auto at = text.find("VmHWM:");
    return at == std::string::npos ? -1L : std::atol(text.c_str() + at + 6);
  };
  const long before = rss_kib();
  std::vector<Client> watchers;
  for (int i = 0; i < 125; ++i) {
    watchers.emplace_back(daemon.socket_path());
    ASSERT_TRUE(watchers.back().send_raw("{\"request\":\"watch\",\"rate_hz\":1000}\n"));
  }
  sleep_s(4.0);  // none of them reads: each fills its socket buffer, then its output cap
  const long after = rss_kib();
  std::printf("[ figures ] VmHWM %ld KiB before, %ld KiB with 125 non-reading 1 kHz watchers\n",
              before, after);
  EXPECT_LT(after - before, 32 * 1024) << before << " -> " << after << " KiB";
  EXPECT_EQ(daemon.status().value("state", ""), "running");
}

// A symlink where the checkpoint is read: refused, logged; the next save replaces the link and
// never writes through it. A symlink planted at the daemon's temporary name: the save refuses.
TEST(Hostile, SymlinkedCheckpointIsNeitherReadNorWrittenThrough) {
  TempDir dir;
  const std::string victim = dir.file("victim");
  write_text(victim, "precious\n");
  DaemonProcess daemon(dir);
  ASSERT_EQ(::symlink(victim.c_str(), daemon.state_file().c_str()), 0);
  daemon.start();
  sleep_s(0.3);
  EXPECT_TRUE(contains(daemon.stderr_text(), "symbolic link")) << daemon.stderr_text();
  // The temporary name of this process, planted before its save.
  const std::string tmp = daemon.state_file() + ".tmp." + std::to_string(daemon.pid());
  ASSERT_EQ(::symlink(victim.c_str(), tmp.c_str()), 0);
  daemon.signal(SIGTERM);
  ASSERT_TRUE(daemon.wait_exit(Seconds(10)));
  EXPECT_EQ(read_text(victim), "precious\n");
  EXPECT_TRUE(contains(daemon.stderr_text(), "refusing to save checkpoint"))
      << daemon.stderr_text();
}

// A FIFO named estimator.state used to hang start-up (SIGTERM blocked). Now: refused, logged,
// cold start, and the daemon answers.
TEST(Hostile, FifoInPlaceOfTheCheckpointDoesNotHangTheStart) {
  TempDir dir;
  DaemonProcess daemon(dir);
  ASSERT_EQ(::mkfifo(daemon.state_file().c_str(), 0644), 0);
  daemon.start();  // throws if the socket does not answer within 15 s
  EXPECT_TRUE(contains(daemon.stderr_text(), "not a regular file")) << daemon.stderr_text();
  EXPECT_TRUE(daemon.wait_status([](const json& s) { return s.value("state", "") == "running"; },
                                 Seconds(5)));
}

// A group- or world-writable state directory lets another user plant those: refused at start,
// before the device is touched, with the remedy.
TEST(Hostile, WorldWritableStateDirectoryIsRefused) {
  TempDir dir;
  DaemonOptions options;
  options.wait_ready = false;
  DaemonProcess daemon(dir, json::object(), options);
  ASSERT_EQ(::chmod(daemon.state_dir().c_str(), 0777), 0);
  daemon.start();
  const auto code = daemon.wait_exit(Seconds(10));
  ASSERT_TRUE(code);
  EXPECT_NE(*code, 0);
  EXPECT_TRUE(contains(daemon.stderr_text(), "chmod go-w")) << daemon.stderr_text();
}

// Checkpoints with a valid checksum but absurd θ̂ (1e300, measured: ε ≈ −2e295 while
// `running`) or learned on another driver: refused, cold start.
TEST(Hostile, PoisonedCheckpointIsRefused) {
  for (const bool other_driver : {false, true}) {
    TempDir dir;
    DaemonProcess daemon(dir);
    daemon::state::Checkpoint c;
    c.theta_hat = {1247, 0.8, 1813, 0.1, 0.0594, 1.1};
    if (!other_driver) c.theta_hat[0] = 1e300;
    for (int i = 0; i < 4; ++i) c.info_mech[static_cast<std::size_t>(i * 5)] = 1.0;
    c.info_thermal = {1.0, 0.0, 0.0, 1.0};
    c.driver = other_driver ? "can" : "sim";
    daemon::state::save_checkpoint(daemon.state_file(), c);
    daemon.start();
    const json e = daemon.estimate();
    const std::string log = daemon.stderr_text();
    EXPECT_TRUE(contains(log, "refusing checkpoint")) << log;
    EXPECT_TRUE(contains(log, other_driver ? "driver 'can'" : "theta_hat[0]")) << log;
    EXPECT_FALSE(contains(log, "warm start from")) << log;
    EXPECT_LT(std::fabs(e["theta_hat"][0].get<double>()), 1e6) << e.dump();
  }
}

// Right after a warm start, before the loop's first cycle, clients already see the restored θ̂
// (test e2e.Lifecycle.SigtermCheckpointWarmStartAndCorruptState failed 2 of 6 runs on this).
TEST(Hostile, RestoredThetaIsPublishedBeforeTheSocketAccepts) {
  TempDir dir;
  DaemonProcess daemon(dir, {{"excitation", {{"enabled", false}}}});
  daemon::state::Checkpoint c;
  c.theta_hat = {1247, 0.8, 1813, 0.1, 0.0594, 1.1};
  for (int i = 0; i < 4; ++i) c.info_mech[static_cast<std::size_t>(i * 5)] = 1.0;
  c.info_thermal = {1.0, 0.0, 0.0, 1.0};
  c.driver = "sim";
  daemon::state::save_checkpoint(daemon.state_file(), c);
  for (int run = 0; run < 3; ++run) {
    daemon.start();  // returns as soon as the socket answers
    const json e = daemon.estimate();
    EXPECT_NEAR(e["theta_hat"][5].get<double>(), 1.1, 0.05) << "run " << run << ": " << e.dump();
    daemon.kill_now();
  }
}

// Configuration "files" that are no files: refused at once with exit 78 (no bad_alloc, no hang,
// no all-defaults run from a directory). An empty socket.mode is refused too.
TEST(Hostile, ConfigMustBeARegularFileOfSaneSize) {
  TempDir dir;
  const std::string fifo = dir.file("fifo.yaml");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  for (const std::string& path : {std::string("/dev/zero"), fifo, dir.path()}) {
    const ProcessResult r = run_process({estimatord_path(), "--config", path}, Seconds(10));
    EXPECT_EQ(r.exit_code, 78) << path << ": " << r.err;
    EXPECT_TRUE(contains(r.err, "not a regular file")) << path << ": " << r.err;
  }
  json config = base_config(dir.path());
  config["socket"]["mode"] = "";
  write_config(dir.file("c.yaml"), config);
  const ProcessResult r = run_process({estimatord_path(), "--config", dir.file("c.yaml")});
  EXPECT_EQ(r.exit_code, 78) << r.err;
  EXPECT_TRUE(contains(r.err, "socket.mode")) << r.err;
}

// A daemon run by hand whose log pipe closes (`scp-estimatord ... | head`) used to die of SIGPIPE
// at its next log line, skipping the 0 V of shutdown. SIGPIPE is ignored now.
TEST(Hostile, ClosedLogPipeDoesNotKillTheDaemon) {
  TempDir dir;
  const std::string state = dir.file("state");
  ::mkdir(state.c_str(), 0755);
  write_config(dir.file("c.yaml"), base_config(dir.path()));
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  const std::string exe = estimatord_path();
  const std::string config = dir.file("c.yaml");
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::dup2(fds[1], 1);
    ::dup2(fds[1], 2);
    ::close(fds[0]);
    ::close(fds[1]);
    ::execl(exe.c_str(), exe.c_str(), "--config", config.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  ::close(fds[0]);  // nobody reads the log: every write gets EPIPE (and SIGPIPE)
  ::close(fds[1]);
  bool answered = false;
  for (int i = 0; i < 500 && !answered; ++i) {
    try {
      Client c(dir.path() + "/d.sock");
      answered = true;
    } catch (const std::exception&) {
      sleep_s(0.01);
    }
  }
  ::kill(pid, SIGHUP);  // logs the reload into the dead pipe
  sleep_s(0.3);
  int status = 0;
  const pid_t gone = ::waitpid(pid, &status, WNOHANG);
  EXPECT_TRUE(answered);
  EXPECT_EQ(gone, 0) << "the daemon died: "
                     << (WIFSIGNALED(status) ? strsignal(WTERMSIG(status)) : "exited");
  ::kill(pid, SIGTERM);
  ::waitpid(pid, &status, 0);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << status;
}

// Bytes after a NUL were ignored ("status\0garbage" answered as status): now an ERROR.
TEST(Hostile, NulInARequestIsAnError) {
  TempDir dir;
  DaemonProcess daemon(dir);
  daemon.start();
  Client client(daemon.socket_path());
  const char raw[] = "{\"request\":\"status\"}\0garbage\n";
  ASSERT_TRUE(client.send_raw(std::string(raw, sizeof raw - 1)));
  const json reply = client.read_json();
  EXPECT_EQ(reply.value("class", ""), "ERROR") << reply.dump();
  EXPECT_TRUE(contains(reply.value("message", ""), "NUL")) << reply.dump();
}

}  // namespace
}  // namespace scp::test

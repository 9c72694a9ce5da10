// The link as it is in the field (issue 9): late replies, exceptions, a dead or stalled slave, a
// lost server, a daemon killed outright. Each test is judged from both sides: the peer logs every
// command it received (and those it left unanswered), the daemon's STATUS says what the device
// acknowledged, and its log must not claim a 0 V it could not deliver.

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>

#include "e2e_configs.hpp"
#include "e2e_util.hpp"
#include "tests/support/peer_required.hpp"

namespace scp::test {
namespace {

using Clock = std::chrono::steady_clock;

std::string state_of(const nlohmann::json& s) {
  return s.is_object() ? s.value("state", "") : "";
}

// How a lab configures a TCP DAQ on a shared, loaded machine (with a 10 ms period and a 4 ms
// timeout): 8 failed transactions in a row tolerated, 80 ms, below safety.stale_timeout_s.
const std::string kTolerant = "    max_consecutive_failures: 8\n";

// A real-time daemon (5 ms period, 2 ms Modbus timeout) on a scp-simdaq started with `peer_args`.
struct LinkRun {
  double timeout = 0.002;
  TempDir dir;
  RunSetup setup;
  std::string log;
  std::string peer_config;
  std::unique_ptr<ChildProcess> peer;
  std::unique_ptr<ChildProcess> daemon;
  int port = -1;
  std::int64_t peer_started_ns = 0;

  explicit LinkRun(const std::string& extra_map = "", double period_s = 0.005,
                   double timeout_s = 0.002)
      : timeout(timeout_s) {
    setup.period_s = period_s;
    setup.socket_path = dir.file("sock");
    setup.state_dir = dir.path().string();
    setup.recover_after_s = 0.5;
    log = dir.file("commands.csv");
    peer_config =
        dir.write("sd.yaml", modbus_tcp_yaml(setup, 1502, kFloat32Map + extra_map, timeout));
  }
  void start_peer(std::vector<std::string> args, int at_port = 0) {
    std::vector<std::string> argv = {"--config",      peer_config,
                                     "--listen",      "127.0.0.1:" + std::to_string(at_port),
                                     "--command-log", log};
    argv.insert(argv.end(), args.begin(), args.end());
    peer_started_ns = unix_now_ns();
    peer = std::make_unique<ChildProcess>(simdaq_realtime(argv));
    ASSERT_TRUE(peer->wait_for("listening on", 10.0)) << peer->output();
    port = printed_port(peer->output());
  }
  void start_daemon(const std::string& extra_map = "", const std::string& log_level = "") {
    std::vector<std::string> argv = {
        kDaemon, "--config",
        dir.write("d.yaml", modbus_tcp_yaml(setup, port, kFloat32Map + extra_map, timeout))};
    if (!log_level.empty()) argv.insert(argv.end(), {"--log-level", log_level});
    daemon = std::make_unique<ChildProcess>(argv);
  }
  template <typename Pred>
  nlohmann::json wait_status_where(Pred pred, double timeout_s) {
    return wait_status(setup.socket_path, timeout_s, [&](const auto& s) { return pred(s); });
  }
  nlohmann::json wait_state(const std::string& state, double timeout_s) {
    return wait_status(setup.socket_path, timeout_s,
                       [&](const auto& s) { return state_of(s) == state; });
  }
  // The fault a peer injects after 2 s of its own time: anything from 1.5 s on is that one, not
  // a start-up hiccup of the 2 ms link (a stress-suite round read the start-up fault).
  nlohmann::json wait_injected_fault(double timeout_s) {
    return wait_fault_since(setup.socket_path, peer_started_ns + 1'500'000'000, timeout_s);
  }
  // The last command the peer applied (answered) before `before_s` of its wall time.
  double last_applied_before(double before_s) const {
    double v = -1.0;
    for (const auto& c : read_command_log(log)) {
      if (c.applied() && c.wall_s < before_s) v = c.volts;
    }
    return v;
  }
};

// Done-when of issue 9: a peer answering 1 in 500 replies 1.5x the response timeout late, for
// 60 s: the late replies are recognised by their transaction id, discarded and counted; no
// reconnection, no FAULT. The link is configured as a lab would for a TCP DAQ on a shared,
// loaded machine: 10 ms period, 4 ms timeout, 8 failed transactions in a row tolerated (80 ms,
// below safety.stale_timeout_s). Before issue 9 every late reply cost the connection.
TEST(E2eLink, LateRepliesAreDiscardedAndCountedWithoutReconnectsOrFaults) {
  LinkRun run("", 0.01, 0.004);
  run.start_peer({"--late-every", "500", "--late-factor", "1.5"});
  run.start_daemon(kTolerant);
  const auto up = run.wait_state("running", 10.0);
  ASSERT_EQ(state_of(up), "running") << up.dump() << run.daemon->output();
  const auto end = Clock::now() + std::chrono::seconds(60);
  int polls = 0, not_running = 0;
  nlohmann::json last;
  while (Clock::now() < end) {
    if (auto s = status(run.setup.socket_path)) {
      last = *s;
      ++polls;
      if (state_of(last) != "running") ++not_running;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  ASSERT_TRUE(last.is_object());
  const auto& d = last["driver_stats"];
  run.peer->stop(SIGTERM);
  const std::string peer_out = run.peer->output();
  const auto at = peer_out.find(" replies sent late");
  ASSERT_NE(at, std::string::npos) << peer_out;
  const long long sent_late = std::atoll(peer_out.c_str() + peer_out.rfind(", ", at) + 2);
  const std::string log = run.daemon->output();
  std::printf(
      "[ figures ] 60 s: %lld replies sent late by the peer, %llu recognised late by the "
      "daemon, %llu reconnects, %llu read errors, %llu write errors, %d of %d polls not "
      "running\n",
      sent_late, d.value("late_replies", 0ULL), d.value("reconnects", 0ULL),
      d.value("read_errors", 0ULL), d.value("write_errors", 0ULL), not_running, polls);
  EXPECT_EQ(d.value("reconnects", -1), 0) << last.dump();
  EXPECT_EQ(not_running, 0) << last.dump();
  EXPECT_EQ(log.find("FAULT"), std::string::npos) << log;
  EXPECT_GE(sent_late, 20);  // 60 s x 200 requests/s / 500 = 24
  // Every late reply the peer sent before the last status was recognised (the last one or two
  // may still have been in flight). A loaded machine makes a few more replies late by itself.
  EXPECT_GE(d.value("late_replies", 0LL), sent_late - 2) << last.dump();
}

// RTU has no transaction id: a reply that comes after its timeout lands in the next
// transaction's wait (libmodbus rejects it by function code) or is flushed before the next
// request; either way it costs a failed transaction, never the link or a fault. 20 s, a socat pty
// pair, 20 ms period, 8 ms timeout as in config/modbus-rtu.yaml, 1 in 100 replies 1.5x late.
// A dead slave still faults within safety.stale_timeout_s (0.1 s, 5 cycles).
TEST(E2eLink, RtuLateRepliesCostATransactionNotTheLink) {
  TempDir dir;
  RunSetup setup;
  setup.period_s = 0.02;
  setup.socket_path = dir.file("sock");
  setup.state_dir = dir.path().string();
  ChildProcess socat(
      with_realtime_priority({"/usr/bin/socat", "-d", "-d", "pty,raw,echo=0", "pty,raw,echo=0"}));
  if (!socat.wait_for("starting data transfer", 10.0)) {
    SCP_PEER_MISSING("socat: " << socat.output());
  }
  const auto ptys = printed_ptys(socat.output());
  ASSERT_EQ(ptys.size(), 2U) << socat.output();
  ChildProcess peer(simdaq_realtime(
      {"--config", dir.write("sd.yaml", modbus_rtu_yaml(setup, ptys[0], kFloat32Map, 0.008)),
       "--late-every", "100", "--late-factor", "1.5"}));
  ASSERT_TRUE(peer.wait_for("serving", 10.0)) << peer.output();
  // A pty chain passes the kernel's tty workqueue four times per transaction (see
  // modbus_rtu_realtime_yaml): 8 failures in a row tolerated, as for the real-time RTU runs.
  ChildProcess daemon(
      {kDaemon, "--config",
       dir.write("d.yaml",
                 modbus_rtu_yaml(setup, ptys[1], kFloat32Map + "    max_consecutive_failures: 8\n",
                                 0.008))});
  const auto up =
      wait_status(setup.socket_path, 10.0, [](const auto& s) { return state_of(s) == "running"; });
  ASSERT_EQ(state_of(up), "running") << up.dump() << daemon.output();
  const auto end = Clock::now() + std::chrono::seconds(20);
  int not_running = 0;
  nlohmann::json last;
  while (Clock::now() < end) {
    if (auto s = status(setup.socket_path)) {
      last = *s;
      if (state_of(last) != "running") ++not_running;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  peer.stop(SIGTERM);
  const auto& d = last["driver_stats"];
  std::printf("[ figures ] RTU 20 s: %s; %llu reconnects, %llu read errors, %llu write errors\n",
              peer.output().substr(peer.output().rfind("stopped")).c_str(),
              d.value("reconnects", 0ULL), d.value("read_errors", 0ULL),
              d.value("write_errors", 0ULL));
  EXPECT_EQ(d.value("reconnects", -1), 0) << last.dump();
  EXPECT_EQ(not_running, 0) << last.dump();
  EXPECT_EQ(daemon.output().find("FAULT"), std::string::npos) << daemon.output();
  EXPECT_GE(d.value("read_errors", 0) + d.value("write_errors", 0), 10) << last.dump();
}

// Read exception 4 (a failed input module) while writes still work: FAULT names the exception,
// the 0 V write reaches the device (peer's log), STATUS says 0 V confirmed.
TEST(E2eLink, ReadExceptionFaultsWithTheExceptionNamedAndZeroVoltsDelivered) {
  LinkRun run("", 0.01, 0.004);
  run.start_peer({"--exception-after", "2", "--fault-duration", "1.5", "--exception-code", "4",
                  "--exception-reads-only"});
  run.start_daemon(kTolerant);
  ASSERT_EQ(state_of(run.wait_state("running", 10.0)), "running") << run.daemon->output();
  const auto fault = run.wait_injected_fault(10.0);
  ASSERT_EQ(state_of(fault), "fault") << fault.dump();
  EXPECT_NE(fault.value("fault_reason", "").find("exception 4 (server device failure)"),
            std::string::npos)
      << fault.dump();
  EXPECT_EQ(fault.value("output", ""), "confirmed") << fault.dump();
  EXPECT_EQ(fault.value("voltage", -1.0), 0.0) << fault.dump();
  bool zero_applied = false, excited_before = false;
  for (const auto& c : read_command_log(run.log)) {
    if (c.wall_s < 2.0 && c.volts > 0.1) excited_before = true;
    if (c.wall_s >= 2.0 && c.wall_s < 3.5 && c.applied() && c.volts == 0.0) zero_applied = true;
  }
  EXPECT_TRUE(excited_before);
  EXPECT_TRUE(zero_applied) << "no 0 V write reached the peer in the exception window";
}

// Exceptions to every request (writes too): 0 V cannot be delivered, and STATUS says so with the
// voltage the device last acknowledged, the one in the peer's log.
TEST(E2eLink, ExceptionToEveryRequestLeavesTheOutputUnconfirmed) {
  LinkRun run("", 0.01, 0.004);
  run.start_peer({"--exception-after", "2", "--exception-code", "4"});
  run.start_daemon(kTolerant);
  ASSERT_EQ(state_of(run.wait_state("running", 10.0)), "running") << run.daemon->output();
  const auto fault = run.wait_injected_fault(10.0);
  ASSERT_EQ(state_of(fault), "fault") << fault.dump();
  EXPECT_EQ(fault.value("output", ""), "unconfirmed") << fault.dump();
  const double held = run.last_applied_before(1e9);
  EXPECT_GT(held, 0.0);
  // The peer logs the float32 it decoded; the daemon the double it encoded.
  EXPECT_NEAR(fault.value("voltage", -1.0), held, 1e-6 * held) << fault.dump();
  EXPECT_EQ(fault.value("voltage_command", -1.0), 0.0) << fault.dump();
}

// A slave that stops answering (a stall of 1.5 s, then answers again): the daemon attempts 0 V
// on the dying link (the peer sees it, unanswered), reports the output unconfirmed while it
// cannot deliver it, and after the stall writes 0 V before anything else.
TEST(E2eLink, StalledSlaveGetsZeroVoltsAttemptedThenZeroFirstAfterReconnect) {
  LinkRun run;
  run.start_peer({"--fault-after", "2", "--fault-duration", "1.5"});
  run.start_daemon();
  ASSERT_EQ(state_of(run.wait_state("running", 10.0)), "running") << run.daemon->output();
  const auto fault = run.wait_injected_fault(10.0);
  ASSERT_EQ(state_of(fault), "fault") << fault.dump();
  EXPECT_EQ(fault.value("output", ""), "unconfirmed") << fault.dump();
  EXPECT_NE(fault.value("fault_reason", "").find("no reply"), std::string::npos) << fault.dump();
  // Whole, not cut mid-word at 127 bytes.
  EXPECT_NE(fault.value("fault_reason", "").find("link dropped, reconnecting"), std::string::npos)
      << fault.dump();
  ASSERT_EQ(state_of(run.wait_state("running", 15.0)), "running") << run.daemon->output();
  const auto cmds = read_command_log(run.log);
  bool zero_attempted = false;
  const LoggedCommand* first_after = nullptr;
  double held = -1.0;
  for (const auto& c : cmds) {
    if (c.note == "unanswered" && c.volts == 0.0) zero_attempted = true;
    if (c.applied() && c.wall_s < 2.0) held = c.volts;
    if (c.applied() && c.wall_s >= 3.5 && first_after == nullptr) first_after = &c;
  }
  EXPECT_TRUE(zero_attempted) << "no 0 V write reached the stalled peer";
  EXPECT_GT(held, 0.0);
  ASSERT_NE(first_after, nullptr);
  EXPECT_EQ(first_after->volts, 0.0) << "first command after the stall at " << first_after->wall_s;
}

// The server dies (link lost): STATUS shows the voltage the device last acknowledged and
// "unconfirmed"; SIGTERM then must not log "output at 0 V".
TEST(E2eLink, LinkLostThenSigtermLogsTheTruthAboutTheOutput) {
  LinkRun run;
  run.start_peer({});
  run.start_daemon();
  ASSERT_EQ(state_of(run.wait_state("running", 10.0)), "running") << run.daemon->output();
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  const std::int64_t killed_ns = unix_now_ns();
  run.peer->stop(SIGKILL);
  const auto fault = wait_fault_since(run.setup.socket_path, killed_ns, 10.0);
  ASSERT_EQ(state_of(fault), "fault") << fault.dump();
  EXPECT_EQ(fault.value("output", ""), "unconfirmed") << fault.dump();
  const double held = run.last_applied_before(1e9);
  EXPECT_GT(held, 0.0);
  EXPECT_NEAR(fault.value("voltage", -1.0), held, 1e-6 * held) << fault.dump();
  run.daemon->stop(SIGTERM);
  const std::string log = run.daemon->output();
  // The shutdown line; a start-up hiccup's FAULT line may truthfully say "output at 0 V".
  EXPECT_EQ(log.find("stopped; output at 0 V"), std::string::npos) << log;
  EXPECT_NE(log.find("stopped; output UNCONFIRMED"), std::string::npos) << log;
}

// A free TCP port on the loopback: bound and released, so nothing listens there.
int free_loopback_port() {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof a;
  bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  ::close(fd);
  return ntohs(a.sin_port);
}

// A DAQ started 1.5 s after the daemon (issue 9): the daemon awaits it in STARTING at 0 V,
// saying why in STATUS and in its log, without a fault; once the DAQ answers, its first command
// is 0 V, then it runs. driver.start_timeout_s is 0 (the default): no limit. The link is a lab's
// on a loaded machine: what is tested is the wait, not whether a 2 ms link hiccups just after it
// (a full suite beside a Monte Carlo run, three busy processes on two cores, faulted it 200 ms
// after the DAQ answered: four 2 ms transactions in a row unanswered).
TEST(E2eLink, DaqStartedLateIsAwaitedInStartingThenRuns) {
  LinkRun run("", 0.01, 0.004);
  run.port = free_loopback_port();
  const auto t0 = Clock::now();
  run.start_daemon(kTolerant, "info");
  const auto waiting = run.wait_status_where(
      [](const nlohmann::json& s) {
        return s.value("waiting_for_device", "first reading") != "first reading";
      },
      10.0);
  ASSERT_EQ(state_of(waiting), "starting") << waiting.dump() << run.daemon->output();
  EXPECT_NE(waiting.value("waiting_for_device", "").find("no answer from tcp 127.0.0.1:"),
            std::string::npos)
      << waiting.dump();
  EXPECT_EQ(waiting.value("voltage_command", -1.0), 0.0) << waiting.dump();
  std::this_thread::sleep_until(t0 + std::chrono::milliseconds(1500));
  // Still awaited, never a fault, however long it takes.
  const auto still = status(run.setup.socket_path);
  ASSERT_TRUE(still.has_value());
  EXPECT_EQ(state_of(*still), "starting") << still->dump();
  EXPECT_EQ(still->value("fault_count", -1), 0) << still->dump();
  run.start_peer({}, run.port);
  const auto up = run.wait_state("running", 15.0);
  ASSERT_EQ(state_of(up), "running") << up.dump() << run.daemon->output();
  EXPECT_EQ(up.value("fault_count", -1), 0) << up.dump();
  EXPECT_FALSE(up.contains("waiting_for_device")) << up.dump();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const auto cmds = read_command_log(run.log);
  ASSERT_FALSE(cmds.empty());
  EXPECT_EQ(cmds.front().volts, 0.0);
  EXPECT_GT(cmds.back().volts, 0.0);
  run.daemon->stop(SIGTERM);
  const std::string log = run.daemon->output();
  EXPECT_NE(log.find("waiting for modbus tcp 127.0.0.1:"), std::string::npos) << log;
  EXPECT_NE(log.find("driver: reconnection attempt "), std::string::npos) << log;
  EXPECT_NE(log.find("answered after"), std::string::npos) << log;
  EXPECT_EQ(log.find("FAULT"), std::string::npos) << log;
}

// driver.start_timeout_s bounds the wait: a DAQ still absent after 1 s makes the daemon exit with
// 69 (EX_UNAVAILABLE, which the unit does not restart on), naming the key and the remedy. A DAQ
// that appears afterwards on that port receives nothing: no reconnection thread outlived the exit.
TEST(E2eLink, DaqAbsentPastStartTimeoutExits69) {
  LinkRun run;
  run.port = free_loopback_port();
  std::string yaml = modbus_tcp_yaml(run.setup, run.port, kFloat32Map, run.timeout);
  const std::string head = "driver:\n  type: modbus\n";
  ASSERT_NE(yaml.find(head), std::string::npos);
  yaml.replace(yaml.find(head), head.size(), head + "  start_timeout_s: 1\n");
  const auto t0 = Clock::now();
  run.daemon = std::make_unique<ChildProcess>(std::vector<std::string>{
      kDaemon, "--config", run.dir.write("d.yaml", yaml), "--log-level", "info"});
  const int code = run.daemon->wait_exit(15.0);
  const double took = std::chrono::duration<double>(Clock::now() - t0).count();
  const std::string log = run.daemon->output();
  std::printf("[ figures ] start_timeout_s 1: exit %d after %.2f s\n", code, took);
  EXPECT_EQ(code, 69) << log;
  EXPECT_GE(took, 1.0) << log;
  EXPECT_LT(took, 4.0) << log;  // 1 s, the start-up and the shutdown on a loaded machine
  EXPECT_NE(log.find("did not answer within driver.start_timeout_s = 1 s"), std::string::npos)
      << log;
  EXPECT_NE(log.find("raise driver.start_timeout_s"), std::string::npos) << log;
  EXPECT_NE(log.find("no command reached it"), std::string::npos) << log;
  run.start_peer({}, run.port);
  std::this_thread::sleep_for(std::chrono::milliseconds(1000));
  EXPECT_TRUE(read_command_log(run.log).empty()) << "a write reached the DAQ after the exit";
}

// A second daemon started by mistake on the same socket and state, or one whose socket directory
// is missing, must refuse before it opens the device: the peer it points at receives nothing
// (before issue 9 it got two 0 V writes into the running bench's command stream).
TEST(E2eLink, RefusedStartsNeverTouchTheDevice) {
  // The running bench is configured as a lab would on a loaded machine: what is tested is the
  // refused starts, not whether a 2 ms link hiccups (a stress-suite round faulted it at start-up).
  LinkRun first("", 0.01, 0.004);
  first.start_peer({});
  first.start_daemon(kTolerant);
  ASSERT_EQ(state_of(first.wait_state("running", 10.0)), "running") << first.daemon->output();

  LinkRun second;
  second.start_peer({});
  second.setup.socket_path = first.setup.socket_path;  // the same bench's socket and state
  second.setup.state_dir = first.setup.state_dir;
  second.start_daemon();
  EXPECT_NE(second.daemon->wait_exit(10.0), 0);
  EXPECT_NE(second.daemon->output().find("another scp-estimatord"), std::string::npos)
      << second.daemon->output();

  LinkRun third;
  third.start_peer({});
  third.setup.socket_path = third.dir.file("missing/sock");
  third.start_daemon();
  EXPECT_NE(third.daemon->wait_exit(10.0), 0);
  EXPECT_NE(third.daemon->output().find("does not exist"), std::string::npos)
      << third.daemon->output();

  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_TRUE(read_command_log(second.log).empty()) << "the second daemon wrote to its device";
  EXPECT_TRUE(read_command_log(third.log).empty()) << "the daemon without socket directory wrote";
  EXPECT_EQ(state_of(*status(first.setup.socket_path)), "running");
}

// The device-side watchdog: the daemon feeds the DAQ's heartbeat register; when the daemon is
// SIGKILLed (no shutdown path runs at all) the DAQ's own watchdog brings the output to 0 V.
TEST(E2eLink, DeviceWatchdogDropsTheOutputWhenTheDaemonIsKilled) {
  // 10 ms: one read, the command and the heartbeat (3 x 2 ms) fit the period.
  const std::string heartbeat = "    watchdog: {register: 100, every_cycles: 5}\n";
  LinkRun run(heartbeat, 0.01);
  run.start_peer({"--watchdog-timeout", "0.3", "--watchdog-register", "100"});
  run.start_daemon(heartbeat);
  ASSERT_EQ(state_of(run.wait_state("running", 10.0)), "running") << run.daemon->output();
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  // Fed every 50 ms, the 0.3 s watchdog never tripped while the daemon lived.
  bool excited = false;
  for (const auto& c : read_command_log(run.log)) {
    excited = excited || c.volts > 0.1;
    if (excited) {
      EXPECT_NE(c.note, "watchdog") << "tripped at " << c.wall_s << " while fed";
    }
  }
  EXPECT_TRUE(excited);
  run.daemon->stop(SIGKILL);
  std::this_thread::sleep_for(std::chrono::milliseconds(800));
  run.peer->stop(SIGTERM);
  const auto cmds = read_command_log(run.log);
  ASSERT_FALSE(cmds.empty());
  double held = -1.0;
  for (const auto& c : cmds) {
    if (c.note.empty()) held = c.volts;
  }
  EXPECT_GT(held, 0.0) << "the daemon was not exciting when killed";
  EXPECT_EQ(cmds.back().note, "watchdog");
  EXPECT_EQ(cmds.back().volts, 0.0);
}

}  // namespace
}  // namespace scp::test

// Modbus RTU against a slave nobody here wrote (issue 31): pymodbus's RTU server with its own
// register map and plant, behind a 115200 Bd line (tests/modbus/serial_line_emulator.cpp), polled
// first by mbpoll (libmodbus, an ordinary master) and then by the daemon configured as a new user
// would from config/modbus-rtu.yaml. The daemon must fail no more often than an ordinary master
// on the same line in the same run, keep the line's inter-frame silence, stay RUNNING and never
// fall a period behind.

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include "e2e_configs.hpp"
#include "e2e_util.hpp"
#include "tests/support/peer_required.hpp"

namespace scp::test {
namespace {

using Clock = std::chrono::steady_clock;

// The run: 100 Hz, a 5 ms response timeout, one 10-register read and one single-register
// write per cycle, 60 s; mbpoll polls the same 10 registers every 10 ms for half as long.
constexpr double kPeriodS = 0.01;
constexpr double kTimeoutS = 0.005;
constexpr double kDaemonS = 60.0;
constexpr double kMbpollS = 30.0;

int free_tcp_port() {
  const int s = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  bind(s, reinterpret_cast<sockaddr*>(&a), sizeof a);
  socklen_t len = sizeof a;
  getsockname(s, reinterpret_cast<sockaddr*>(&a), &len);
  ::close(s);
  return ntohs(a.sin_port);
}

// mbpoll's closing statistics: "N frames transmitted, M received, E errors, ...".
struct PollCount {
  long long sent = -1;
  long long received = -1;
};
PollCount mbpoll_count(const std::string& out) {
  const std::regex re("(\\d+) frames transmitted, (\\d+) received");
  std::smatch m;
  PollCount c;
  if (std::regex_search(out, m, re)) {
    c.sent = std::stoll(m[1]);
    c.received = std::stoll(m[2]);
  }
  return c;
}

// The emulator's latest report: master frames, and those that began less than t3.5 after the
// previous frame on the line.
struct LineCount {
  long long master_frames = -1;
  long long short_silences = -1;
};
LineCount line_count(const std::string& out) {
  const std::regex re(
      "serial line: (\\d+) master frames, \\d+ slave frames; (\\d+) master frames began less");
  LineCount c;
  for (auto it = std::sregex_iterator(out.begin(), out.end(), re); it != std::sregex_iterator();
       ++it) {
    c.master_frames = std::stoll((*it)[1]);
    c.short_silences = std::stoll((*it)[2]);
  }
  return c;
}

LineCount line_report_now(ChildProcess& line) {
  const auto reports = [&] {
    const std::string& out = line.output();
    return std::count(out.begin(), out.end(), '\n');
  };
  const auto before = reports();
  kill(line.pid(), SIGUSR1);
  for (int i = 0; i < 250 && reports() == before; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return line_count(line.output());
}

// config/modbus-rtu.yaml as shipped, with what this set-up dictates: the slave's line, unit and
// map, the period and timeout, and the test's socket and state paths.
std::string shipped_rtu_yaml(const RunSetup& setup, const std::string& device) {
  YAML::Node c = YAML::LoadFile(std::string(SCP_SOURCE_DIR) + "/config/modbus-rtu.yaml");
  c["loop"]["period_s"] = kPeriodS;
  c["loop"]["realtime"]["lock_memory"] = false;
  YAML::Node m = c["driver"]["modbus"];
  m["rtu"]["device"] = device;
  m["unit_id"] = 17;
  m["response_timeout"] = kTimeoutS;
  // tests/modbus/pymodbus_rtu_slave.py's map: holding registers, the signals at 1000-1009 with
  // a status word nobody reads between ẋ and the read-back (one 10-register request), the
  // command in millivolts at 1100 (function 6).
  YAML::Node s = m["signals"];
  const auto holding_float = [](int address) {
    YAML::Node n;
    n["table"] = "holding";
    n["address"] = address;
    n["type"] = "float32";
    n["word_order"] = "ab";
    return n;
  };
  s["x"] = holding_float(1000);
  s["temperature"] = holding_float(1002);
  s["xdot"] = holding_float(1004);
  s["voltage"] = holding_float(1008);
  YAML::Node command;
  command["address"] = 1100;
  command["type"] = "uint16";
  command["scale"] = 0.001;
  command["min"] = 0.0;
  command["max"] = 10.0;
  m["command"] = command;
  c["socket"]["path"] = setup.socket_path;
  c["socket"]["group"] = "";
  c["state"]["directory"] = setup.state_dir;
  c["state"]["warm_start"] = false;
  YAML::Emitter out;
  out << c;
  return out.c_str();
}

TEST(E2eRtuPeers, DaemonFailsNoMoreOftenThanMbpollOnTheSameLine) {
  const std::string python = "/usr/bin/python3", mbpoll = "/usr/bin/mbpoll";
  if (!executable(python) ||
      std::system("/usr/bin/python3 -c 'import pymodbus.server' >/dev/null 2>&1") != 0) {
    SCP_PEER_MISSING("Debian's python3-pymodbus is not usable: apt install python3-pymodbus");
  }
  if (!executable(mbpoll)) SCP_PEER_MISSING("mbpoll is not installed (apt install mbpoll)");
  TempDir dir;
  const int port = free_tcp_port();
  ChildProcess slave(with_realtime_priority(
      {python, SCP_PYMODBUS_RTU_SLAVE, "socket:127.0.0.1:" + std::to_string(port)}));
  ASSERT_TRUE(slave.wait_for("pymodbus rtu slave ready", 15.0)) << slave.output();
  ChildProcess line(with_realtime_priority(
      {SCP_SERIAL_LINE_EMULATOR, "--baud", "115200", "--slave-port", std::to_string(port)}));
  ASSERT_TRUE(line.wait_for("starting data transfer", 10.0)) << line.output();
  const auto ptys = printed_ptys(line.output());
  ASSERT_EQ(ptys.size(), 1U) << line.output();

  // The baseline: an ordinary master (libmodbus) at the loop's priority, on the same line.
  std::vector<std::string> poll = {mbpoll, "-m", "rtu", "-b", "115200", "-P",   "none",
                                   "-a",   "17", "-t",  "4",  "-r",     "1001", "-c",
                                   "10",   "-l", "10",  "-o", "0.01",   ptys[0]};
  if (geteuid() == 0) poll.insert(poll.begin(), {"/usr/bin/chrt", "-f", "80"});
  ChildProcess baseline(poll);
  // mbpoll prints every poll: read its output as it comes, or it blocks on a full pipe.
  const auto polled_until = Clock::now() + std::chrono::duration<double>(kMbpollS);
  while (Clock::now() < polled_until) {
    baseline.wait_for("\x01", 0.2);  // a pattern it never prints: drains for 0.2 s
  }
  baseline.stop(SIGINT);
  const PollCount polls = mbpoll_count(baseline.output());
  ASSERT_GT(polls.sent, 0.5 * kMbpollS / 0.02) << baseline.output().substr(0, 2000);
  const LineCount before = line_report_now(line);

  RunSetup setup;
  setup.socket_path = dir.file("sock");
  setup.state_dir = dir.path().string();
  ChildProcess daemon({kDaemon, "--config", dir.write("d.yaml", shipped_rtu_yaml(setup, ptys[0]))});
  const auto up = wait_status(setup.socket_path, 15.0,
                              [](const auto& s) { return s.value("state", "") == "running"; });
  ASSERT_EQ(up.value("state", ""), "running") << up.dump() << daemon.output();
  const auto end = Clock::now() + std::chrono::duration<double>(kDaemonS);
  int status_polls = 0, not_running = 0;
  nlohmann::json last = up, first_other;
  while (Clock::now() < end) {
    std::this_thread::sleep_for(std::chrono::seconds(1));
    const auto s = status(setup.socket_path);
    ASSERT_TRUE(s) << "the daemon stopped answering: " << daemon.output();
    ++status_polls;
    if (s->value("state", "") != "running") {
      ++not_running;
      if (first_other.is_null()) first_other = *s;
    }
    last = *s;
  }
  const LineCount after = line_report_now(line);
  daemon.stop(SIGTERM);

  const auto& d = last["driver_stats"];
  const auto& l = last["loop"];
  const long long failed = d.value("read_errors", 0LL) + d.value("write_errors", 0LL);
  const long long done = d.value("reads", 0LL) + d.value("writes", 0LL) + failed;
  const double rate = done > 0 ? static_cast<double>(failed) / static_cast<double>(done) : 1.0;
  const long long polls_failed = polls.sent - polls.received;
  // A baseline without a failure bounds its rate by one in as many polls (the rule of one).
  const double baseline_rate =
      static_cast<double>(std::max(polls_failed, 1LL)) / static_cast<double>(polls.sent);
  const double lateness_max_us = l["lateness_us"].value("max", 0.0);
  const long long short_silences = after.short_silences - before.short_silences;
  std::printf(
      "[ figures ] RTU 115200 Bd, pymodbus slave: mbpoll %lld polls, %lld failed (%.3f %%); "
      "daemon %lld transactions, %lld failed (%.3f %%: %lld reads, %lld writes), %lld late "
      "replies, RUNNING at %d of %d polls, lateness max %.0f us, %lld overruns, %lld of %lld "
      "requests sooner than t3.5\n",
      polls.sent, polls_failed, 100.0 * static_cast<double>(polls_failed) / polls.sent, done,
      failed, 100.0 * rate, d.value("read_errors", 0LL), d.value("write_errors", 0LL),
      d.value("late_replies", 0LL), status_polls - not_running, status_polls, lateness_max_us,
      l.value("overruns", 0LL), short_silences, after.master_frames - before.master_frames);
  EXPECT_EQ(not_running, 0) << first_other.dump();
  EXPECT_GT(done, 1.6 * kDaemonS / kPeriodS) << last.dump();  // 2 transactions a cycle, ~all
  EXPECT_LE(rate, 0.002) << last.dump();
  EXPECT_LE(rate, 3.0 * baseline_rate) << last.dump();
  EXPECT_LT(lateness_max_us, kPeriodS * 1e6) << last.dump();
  // A request sent after a timeout can still meet a reply that was later than that (the line
  // showed no byte of it yet): at most one such collision per failed transaction.
  EXPECT_LE(short_silences, failed) << line.output();
}

}  // namespace
}  // namespace scp::test

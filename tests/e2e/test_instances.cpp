// Issue 10, several actuators on one PC: two daemons side by side with their own sockets and
// state; a second daemon on the same state directory refuses to start and names the first (its
// pid, actuator and socket); a checkpoint carries the actuator's identity, so that a warm start
// from another actuator's checkpoint is refused; --instance maps a name to socket and state.

#include <filesystem>

#include "daemon/service/instance.hpp"
#include "tests/e2e/e2e_util.hpp"

namespace scp::test {
namespace {

TEST(Instances, TwoActuatorsSideBySide) {
  TempDir dir_a;
  TempDir dir_b;
  DaemonProcess a(dir_a, {{"actuator", {{"name", "bench-a"}}}});
  DaemonProcess b(dir_b, {{"actuator", {{"name", "bench-b"}}}});
  a.start();
  b.start();
  const auto running = [](const json& s) { return s.value("state", "") == "running"; };
  ASSERT_TRUE(a.wait_status(running, Seconds(10))) << a.stderr_text();
  ASSERT_TRUE(b.wait_status(running, Seconds(10))) << b.stderr_text();
  EXPECT_EQ(a.status().value("actuator", ""), "bench-a");
  EXPECT_EQ(b.status().value("actuator", ""), "bench-b");
  a.signal(SIGTERM);
  b.signal(SIGTERM);
  ASSERT_EQ(a.wait_exit(Seconds(10)), std::optional<int>(0));
  ASSERT_EQ(b.wait_exit(Seconds(10)), std::optional<int>(0));
  EXPECT_EQ(json::parse(read_text(a.state_file())).value("actuator", ""), "bench-a");
  EXPECT_EQ(json::parse(read_text(b.state_file())).value("actuator", ""), "bench-b");
  EXPECT_EQ(json::parse(read_text(b.state_file())).value("endpoint", ""), "sim");
}

TEST(Instances, SecondDaemonOnTheSameStateNamesTheFirst) {
  TempDir dir_a;
  TempDir dir_b;
  DaemonProcess a(dir_a, {{"actuator", {{"name", "bench-a"}}}});
  a.start();
  DaemonOptions no_wait;
  no_wait.wait_ready = false;
  DaemonProcess b(dir_b,
                  {{"actuator", {{"name", "bench-b"}}}, {"state", {{"directory", a.state_dir()}}}},
                  no_wait);
  b.start();
  const auto code = b.wait_exit(Seconds(10));
  ASSERT_TRUE(code) << "the second daemon did not exit";
  EXPECT_NE(*code, 0);
  const std::string log = b.stderr_text();
  EXPECT_TRUE(contains(log, "another scp-estimatord already runs on state directory")) << log;
  EXPECT_TRUE(contains(log, "pid " + std::to_string(a.pid()))) << log;
  EXPECT_TRUE(contains(log, "actuator bench-a")) << log;
  EXPECT_TRUE(contains(log, a.socket_path())) << log;
  // The first daemon still serves and reaches RUNNING (it may still be starting on a loaded
  // machine when the second one gives up).
  const auto first =
      a.wait_status([](const json& st) { return st.value("state", "") == "running"; }, Seconds(10));
  EXPECT_TRUE(first) << "the first daemon was disturbed: " << a.status().dump();
}

TEST(Instances, WarmStartFromAnotherActuatorsCheckpointIsRefused) {
  TempDir dir;
  DaemonProcess a(dir, {{"actuator", {{"name", "bench-a"}}}});
  a.start();
  sleep_s(1.5);
  a.signal(SIGTERM);
  ASSERT_EQ(a.wait_exit(Seconds(10)), std::optional<int>(0)) << a.stderr_text();
  ASSERT_TRUE(std::filesystem::exists(a.state_file()));

  // Another actuator pointed at A's state (A stopped): its checkpoint is not B's estimate.
  TempDir dir_b;
  DaemonProcess b(dir_b,
                  {{"actuator", {{"name", "bench-b"}}}, {"state", {{"directory", a.state_dir()}}}});
  b.start();
  sleep_s(0.3);
  const std::string log = b.stderr_text();
  EXPECT_TRUE(contains(log, "belongs to actuator 'bench-a'")) << log;
  EXPECT_TRUE(contains(log, "starting cold")) << log;
  EXPECT_FALSE(contains(log, "warm start from")) << log;
  b.signal(SIGTERM);
  ASSERT_EQ(b.wait_exit(Seconds(10)), std::optional<int>(0));

  // B's shutdown wrote B's checkpoint; A, back, refuses it likewise. A fresh A checkpoint is
  // accepted (same name, same endpoint).
  a.start();
  sleep_s(0.3);
  EXPECT_TRUE(contains(a.stderr_text(), "belongs to actuator 'bench-b'")) << a.stderr_text();
  a.signal(SIGTERM);
  ASSERT_EQ(a.wait_exit(Seconds(10)), std::optional<int>(0));
  const auto before = a.stderr_text().size();
  a.start();
  sleep_s(0.3);
  EXPECT_TRUE(contains(a.stderr_text().substr(before), "warm start from"))
      << a.stderr_text().substr(before);
}

TEST(Instances, InstanceNameDecidesSocketStateAndName) {
  config::DaemonConfig cfg;
  EXPECT_TRUE(daemon::apply_instance(cfg, "bench-a").empty());
  EXPECT_EQ(cfg.socket.socket_path, "/run/scp-estimator/bench-a.sock");
  EXPECT_EQ(cfg.state.directory, "/var/lib/scp-estimator/bench-a");
  EXPECT_EQ(cfg.actuator.name, "bench-a");
  // A name set in the file stays; socket and state set elsewhere are overridden, with a warning.
  config::DaemonConfig named;
  named.actuator.name = "left-arm";
  named.socket.socket_path = "/tmp/x.sock";
  const auto warnings = daemon::apply_instance(named, "bench-a");
  EXPECT_EQ(named.actuator.name, "left-arm");
  EXPECT_EQ(named.socket.socket_path, "/run/scp-estimator/bench-a.sock");
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_TRUE(contains(warnings[0], "/tmp/x.sock")) << warnings[0];
  EXPECT_FALSE(daemon::instance_name_problem("../etc").empty());
  EXPECT_FALSE(daemon::instance_name_problem("").empty());
  EXPECT_TRUE(daemon::instance_name_problem("bench_2.b").empty());

  // The daemon refuses a bad name as a usage error; the client maps a name to the socket.
  const ProcessResult bad =
      run_process({estimatord_path(), "--instance", "a/b", "--check-config", "/nonexistent.yaml"});
  EXPECT_EQ(bad.exit_code, 64) << bad.err;
  const ProcessResult ctl =
      run_process({estimatorctl_path(), "--instance", "no-such-bench-xyz", "status"});
  EXPECT_EQ(ctl.exit_code, 2) << ctl.err;
  EXPECT_TRUE(contains(ctl.err, "/run/scp-estimator/no-such-bench-xyz.sock")) << ctl.err;
  const ProcessResult both =
      run_process({estimatorctl_path(), "--instance", "a", "--socket", "/tmp/s", "status"});
  EXPECT_EQ(both.exit_code, 64) << both.err;
}

}  // namespace
}  // namespace scp::test

// θ̂ through each transport, in lock-step (scp-simdaq --lockstep, scp-estimatord --offline):
// the same experiment as the in-process simulator, with the registers' or frames' quantization
// and the transport in between. The measured errors are printed for the docs.

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <array>
#include <cmath>
#include <cstdio>

#include "e2e_configs.hpp"
#include "e2e_util.hpp"
#include "tests/support/peer_required.hpp"

namespace scp::test {
namespace {

// 100 s at 500 Hz: the in-process simulator is then within ~1e-4 (config/paper.yaml at 2 ms);
// the tolerance for the paper's experiment at 120 s is 1e-3.
constexpr double kDuration = 100.0;
// A lock-step run takes ~35 s on an idle 2-core machine; at load 14 (every process gets a seventh
// of a core) 65 s over TCP and over 240 s over the pty pair: the wait (and the ctest timeout,
// tests/e2e_drivers/CMakeLists.txt) leave room for a loaded machine.
constexpr double kExitWaitS = 400.0;
// A lock-step run is about values, not timing: transactions a loaded machine loses (RTU over the
// pty pair at load 14: four in a row, each after driver.modbus.offline_response_timeout, which
// dropped the link and ended the run in FAULT) cost a sample each, not the run.
const std::string kLockstepMap = kFloat32Map + "    max_consecutive_failures: 50\n";
// θ from Table I (m = 0.1, R = 1, Cth = 0.9090, λ = 0.054, b = 124.7, k = 181.3, α1 = 0.08,
// α2 = 0.01), computed here: only the in-process simulator reports it to the daemon.
const double kTheta[6] = {124.7 / 0.1, 0.08 / 0.1,      181.3 / 0.1,
                          0.01 / 0.1,  0.0540 / 0.9090, 1.0 / 0.9090};
// Thermal pair: the 1e-3. Mechanical block: the transports' quantization (and, on CAN,
// integer signals) leave ~1e-3 where the in-process simulator reaches ~4e-4 (measured); 3e-3.
constexpr double kTolerance[6] = {3e-3, 3e-3, 3e-3, 3e-3, 1e-3, 1e-3};

std::array<double, 6> rel_error(const nlohmann::json& s) {
  std::array<double, 6> e{};
  for (std::size_t i = 0; i < 6; ++i) {
    e[i] = std::fabs(s["theta_hat"][i].get<double>() - kTheta[i]) / kTheta[i];
  }
  return e;
}

nlohmann::json run_offline(const std::string& config) {
  ChildProcess daemon(
      {kDaemon, "--config", config, "--offline", "--duration", std::to_string(kDuration)});
  const int rc = daemon.wait_exit(kExitWaitS);
  EXPECT_EQ(rc, 0) << daemon.output();
  return last_json_line(daemon.output());
}

void report(const std::string& name, const nlohmann::json& s) {
  std::printf("[measured] %-28s state %s, %.0f s of loop time in %.1f s:", name.c_str(),
              s.value("state", "?").c_str(), s.value("t", 0.0), s.value("wall_time_s", 0.0));
  if (s.contains("theta_hat")) {
    for (const double e : rel_error(s)) std::printf(" %.1e", e);
  }
  std::printf("\n");
}

void expect_converged(const nlohmann::json& s) {
  ASSERT_TRUE(s.contains("theta_hat")) << s.dump();
  EXPECT_EQ(s["state"], "running") << s.dump();
  const auto e = rel_error(s);
  for (std::size_t i = 0; i < 6; ++i) {
    EXPECT_LT(e[i], kTolerance[i]) << "theta" << i + 1 << " " << s.dump();
  }
}

TEST(E2eConvergence, InProcessSimulatorReference) {
  TempDir dir;
  RunSetup setup{.socket_path = dir.file("sock"), .state_dir = dir.path().string()};
  const std::string cfg =
      dir.write("sim.yaml", common_yaml(setup) + "driver:\n  type: sim\n" + sim_yaml(setup));
  const auto s = run_offline(cfg);
  report("in-process sim", s);
  expect_converged(s);
}

TEST(E2eConvergence, ModbusTcpLockstepFloat32) {
  TempDir dir;
  RunSetup setup{.socket_path = dir.file("sock"), .state_dir = dir.path().string()};
  const std::string sd_cfg = dir.write("simdaq.yaml", modbus_tcp_yaml(setup, 1502));
  ChildProcess simdaq({kSimdaq, "--config", sd_cfg, "--listen", "127.0.0.1:0", "--lockstep"});
  ASSERT_TRUE(simdaq.wait_for("listening on", 10.0)) << simdaq.output();
  const int port = printed_port(simdaq.output());
  ASSERT_GT(port, 0) << simdaq.output();
  const auto s = run_offline(dir.write("d.yaml", modbus_tcp_yaml(setup, port, kLockstepMap)));
  report("modbus tcp float32", s);
  expect_converged(s);
}

TEST(E2eConvergence, ModbusRtuOverAPtyPairLockstepFloat32) {
  TempDir dir;
  ChildProcess socat({"/usr/bin/socat", "-d", "-d", "pty,raw,echo=0", "pty,raw,echo=0"});
  if (!socat.wait_for("starting data transfer", 10.0))
    SCP_PEER_MISSING("socat: " << socat.output());
  const auto ptys = printed_ptys(socat.output());
  ASSERT_EQ(ptys.size(), 2U) << socat.output();
  RunSetup setup{.socket_path = dir.file("sock"), .state_dir = dir.path().string()};
  const std::string sd_cfg = dir.write("simdaq.yaml", modbus_rtu_yaml(setup, ptys[0]));
  ChildProcess simdaq({kSimdaq, "--config", sd_cfg, "--lockstep"});
  ASSERT_TRUE(simdaq.wait_for("serving", 10.0)) << simdaq.output();
  // A pty has no baud rate: the run goes as fast as the two processes exchange frames.
  const auto s = run_offline(dir.write("d.yaml", modbus_rtu_yaml(setup, ptys[1], kLockstepMap)));
  report("modbus rtu float32", s);
  expect_converged(s);
}

// scp-simdaq as a lock-step CAN node and the daemon offline on a socket pair, both reading
// `config`; returns the daemon's final JSON line ({} when it failed, with the failure recorded).
nlohmann::json run_can_lockstep(const std::string& config) {
  CanWire wire;
  EXPECT_GE(wire.daemon, 0);
  ChildProcess node(
      {kSimdaq, "--config", config, "--transport", "can", "--device", "fd:3", "--lockstep"},
      wire.node);
  if (!node.wait_for("CAN node on fd 3", 10.0)) {
    ADD_FAILURE() << node.output();
    return nlohmann::json::object();
  }
  ChildProcess daemon(
      {kDaemon, "--config", config, "--offline", "--duration", std::to_string(kDuration)},
      wire.daemon);
  ::close(wire.node);  // only the children hold the ends now: a hang-up ends the node
  wire.node = -1;
  const int rc = daemon.wait_exit(kExitWaitS);
  EXPECT_EQ(rc, 0) << daemon.output();
  return rc == 0 ? last_json_line(daemon.output()) : nlohmann::json::object();
}

TEST(E2eConvergence, CanFramesOverASocketpairLockstepInt32) {
  TempDir dir;
  RunSetup setup{.socket_path = dir.file("sock"), .state_dir = dir.path().string()};
  const auto s = run_can_lockstep(dir.write("can.yaml", can_yaml(setup, 1.0)));
  report("can int32 (1e-11 m, 1e-6 C)", s);
  expect_converged(s);
}

// Lock-step is a contract: each of the daemon's frames steps the node once, so the daemon sees
// every plant step once, whole, and in order, whatever the machine's load. (A node that stepped
// once before the daemon's first frame ran a step ahead: a read then drained x of one step with
// T of the next, at random, and θ̂1..θ̂4 ended anywhere from 2e-4 to 4e-3 off.)
TEST(E2eConvergence, CanLockstepIsBitReproducible) {
  TempDir dir;
  RunSetup setup{.socket_path = dir.file("sock"), .state_dir = dir.path().string()};
  const std::string config = dir.write("can.yaml", can_yaml(setup, 1.0));
  const auto first = run_can_lockstep(config);
  const auto second = run_can_lockstep(config);
  ASSERT_TRUE(first.contains("theta_hat")) << first.dump();
  ASSERT_TRUE(second.contains("theta_hat")) << second.dump();
  EXPECT_EQ(first["theta_hat"], second["theta_hat"]) << first.dump() << "\n" << second.dump();
  EXPECT_EQ(first["updates"], second["updates"]);
}

// The shipped config/can.yaml as a lab would start from it: x in 1 nm and T in 1e-4 °C (int32),
// no ẋ (the loop estimates it), no voltage read-back (the last command, 1 mV steps), default
// estimator gains of the example configs. Only what must change for this test is changed: the
// interface (a socket pair instead of can0), lock-step reads, the socket and state paths.
// (Written when config/can.yaml held only the driver section: the safety defaults then faulted
// the paper's excitation at 55 s, 100 °C.)
std::string shipped_can_yaml(const RunSetup& setup) {
  YAML::Node c = YAML::LoadFile(std::string(SCP_SOURCE_DIR) + "/config/can.yaml");
  c["driver"]["can"]["interface"] = "fd:3";
  c["driver"]["can"]["read_wait_s"] = 1.0;
  c["loop"]["realtime"]["required"] = false;
  c["loop"]["realtime"]["lock_memory"] = false;
  c["socket"]["path"] = setup.socket_path;
  c["socket"]["group"] = "";
  c["state"]["directory"] = setup.state_dir;
  c["state"]["warm_start"] = false;
  c["log_level"] = "warn";
  YAML::Emitter out;
  out << c;
  return out.c_str();
}

TEST(E2eConvergence, ShippedCanConfigConverges) {
  TempDir dir;
  RunSetup setup{.socket_path = dir.file("sock"), .state_dir = dir.path().string()};
  const auto s = run_can_lockstep(dir.write("can.yaml", shipped_can_yaml(setup)));
  report("config/can.yaml as shipped", s);
  expect_converged(s);
}

}  // namespace
}  // namespace scp::test

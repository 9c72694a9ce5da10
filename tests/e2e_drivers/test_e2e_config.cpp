// The configuration mistakes a user is likely to make with a DAQ, refused by
// `scp-estimatord --check-config` (exit 78, EX_CONFIG) with a message that names them.

#include <gtest/gtest.h>

#include <regex>
#include <sstream>

#include "e2e_configs.hpp"
#include "e2e_util.hpp"

namespace scp::test {
namespace {

struct Checked {
  int rc;
  std::string out;
};

Checked check(const TempDir& dir, const std::string& yaml) {
  const std::string path = dir.write("check.yaml", yaml);
  ChildProcess p({kDaemon, "--check-config", path});
  const int rc = p.wait_exit(20.0);
  return {rc, p.output()};
}

RunSetup setup_in(const TempDir& dir) {
  return RunSetup{.socket_path = dir.file("sock"), .state_dir = dir.path().string()};
}

std::string replace(std::string s, const std::string& from, const std::string& to) {
  const auto at = s.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) s.replace(at, from.size(), to);
  return s;
}

TEST(E2eConfig, TheTestConfigurationsAreValid) {
  TempDir dir;
  EXPECT_EQ(check(dir, modbus_tcp_yaml(setup_in(dir), 1502)).rc, 0);
  EXPECT_EQ(check(dir, modbus_rtu_yaml(setup_in(dir), "/dev/null")).rc, 0);
  EXPECT_EQ(check(dir, can_yaml(setup_in(dir), 0.0)).rc, 0);
  // The examples name the service's group and /var/lib/scp-estimator. On a machine without the
  // package (which makes both) --check-config reports those two facts (exit 78), never a key.
  for (const char* example : {"modbus-tcp.yaml", "modbus-rtu.yaml", "can.yaml"}) {
    ChildProcess p({kDaemon, "--check-config", std::string(SCP_SOURCE_DIR) + "/config/" + example});
    const auto rc = p.wait_exit(20.0);
    const std::string out = p.output();
    if (rc == 0) continue;
    EXPECT_EQ(rc, 78) << example << ": " << out;
    EXPECT_EQ(out.find("configuration error"), std::string::npos) << example << ": " << out;
    std::istringstream lines(out);
    for (std::string line; std::getline(lines, line);) {
      if (line.find(": error: ") == std::string::npos) continue;
      EXPECT_TRUE(line.find("socket.group: group 'scp-estimator'") != std::string::npos ||
                  line.find("state.directory: '/var/lib/scp-estimator'") != std::string::npos)
          << example << ": " << line;
    }
  }
}

TEST(E2eConfig, OverlappingRegistersAreRefusedNamingBoth) {
  TempDir dir;
  const auto yaml =
      replace(modbus_tcp_yaml(setup_in(dir), 1502), "temperature: {table: input, address: 2,",
              "temperature: {table: input, address: 1,");
  const auto r = check(dir, yaml);
  EXPECT_EQ(r.rc, 78) << r.out;
  EXPECT_NE(r.out.find("temperature"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("x"), std::string::npos) << r.out;
  EXPECT_TRUE(std::regex_search(r.out, std::regex("overlap|share", std::regex::icase))) << r.out;
}

TEST(E2eConfig, Float32WithoutWordOrderIsRefused) {
  TempDir dir;
  const auto yaml =
      replace(modbus_tcp_yaml(setup_in(dir), 1502),
              "xdot:        {table: input, address: 4, type: float32, word_order: ab}",
              "xdot:        {table: input, address: 4, type: float32}");
  const auto r = check(dir, yaml);
  EXPECT_EQ(r.rc, 78) << r.out;
  EXPECT_NE(r.out.find("word_order"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("xdot"), std::string::npos) << r.out;
}

TEST(E2eConfig, ResponseTimeoutLongerThanThePeriodAllowsIsRefused) {
  TempDir dir;
  RunSetup s = setup_in(dir);
  s.period_s = 0.001;
  const auto r = check(dir, modbus_tcp_yaml(s, 1502, kFloat32Map, 0.004));
  EXPECT_EQ(r.rc, 78) << r.out;
  EXPECT_NE(r.out.find("exceeds the 1 ms loop period"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("response_timeout"), std::string::npos) << r.out;
}

TEST(E2eConfig, ACanFrameIdUsedTwiceIsRefused) {
  TempDir dir;
  // The command frame reuses the x frame's id: the node could not tell them apart.
  const auto yaml = replace(can_yaml(setup_in(dir), 0.0), "command: {frame_id: 0x201",
                            "command: {frame_id: 0x101");
  const auto r = check(dir, yaml);
  EXPECT_EQ(r.rc, 78) << r.out;
  EXPECT_NE(r.out.find("frame_id"), std::string::npos) << r.out;
}

TEST(E2eConfig, TwoCanSignalsSharingBitsAreRefused) {
  TempDir dir;
  const auto yaml = replace(can_yaml(setup_in(dir), 0.0),
                            "xdot: {present: true, frame_id: 0x101, dlc: 8, start_bit: 32",
                            "xdot: {present: true, frame_id: 0x101, dlc: 8, start_bit: 16");
  const auto r = check(dir, yaml);
  EXPECT_EQ(r.rc, 78) << r.out;
  EXPECT_NE(r.out.find("xdot"), std::string::npos) << r.out;
}

TEST(E2eConfig, ACanSignalThatDoesNotFitItsFrameIsRefused) {
  TempDir dir;
  const auto yaml = replace(can_yaml(setup_in(dir), 0.0),
                            "voltage: {present: true, frame_id: 0x102, dlc: 8, start_bit: 32",
                            "voltage: {present: true, frame_id: 0x102, dlc: 8, start_bit: 48");
  const auto r = check(dir, yaml);
  EXPECT_EQ(r.rc, 78) << r.out;
  EXPECT_NE(r.out.find("voltage"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("start_bit"), std::string::npos) << r.out;
}

TEST(E2eConfig, AMalformedInheritedDescriptorIsRefused) {
  TempDir dir;
  const auto yaml =
      replace(can_yaml(setup_in(dir), 0.0), "interface: \"fd:3\"", "interface: \"fd:three\"");
  const auto r = check(dir, yaml);
  EXPECT_EQ(r.rc, 78) << r.out;
  EXPECT_NE(r.out.find("fd:N"), std::string::npos) << r.out;
}

}  // namespace
}  // namespace scp::test

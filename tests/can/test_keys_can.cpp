// The driver.can YAML keys through the lead's Binder: values land in CanSettings, and layout
// mistakes are refused naming the key and its line.

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <string>

#include "daemon/config/binder.hpp"
#include "daemon/config/keys_can.hpp"
#include "tests/support/config_section.hpp"

namespace scp::config {
namespace {

using drivers::can::ByteOrder;
using drivers::can::CanSettings;

CanSettings load(const std::string& yaml) {
  return test::load_section<CanSettings>(yaml, "can", declare_can_keys);
}

std::string error_of(const std::string& yaml) {
  return test::section_error<CanSettings>(yaml, "can", declare_can_keys, "");
}

TEST(KeysCan, DefaultsAreTheDefaultLayout) {
  const CanSettings s = load("can: {}\n");
  const CanSettings d = drivers::can::default_can_settings();
  EXPECT_EQ(s.interface, "can0");
  EXPECT_EQ(s.x.frame_id, d.x.frame_id);
  EXPECT_TRUE(s.x.present);
  EXPECT_FALSE(s.xdot.present);
  EXPECT_EQ(s.command.signal.frame_id, 0x201U);
  EXPECT_DOUBLE_EQ(s.temperature.scale, 1e-4);
}

TEST(KeysCan, ReadsADbcLikeLayout) {
  const CanSettings s = load(
      "can:\n"
      "  interface: vcan0\n"
      "  x: {frame_id: 0x18FF1000, extended: true, start_bit: 7, length_bits: 24,\n"
      "      byte_order: motorola, signed: true, scale: 1.0e-7, offset: 0.001}\n"
      "  temperature: {frame_id: 0x300, start_bit: 0, length_bits: 16, scale: 0.01,\n"
      "                offset: -40, stale_timeout_s: 0.2}\n"
      "  command: {frame_id: 0x301, send_each_cycle: false}\n");
  EXPECT_EQ(s.interface, "vcan0");
  EXPECT_EQ(s.x.frame_id, 0x18FF1000U);
  EXPECT_TRUE(s.x.extended);
  EXPECT_EQ(s.x.byte_order, ByteOrder::big_endian);
  EXPECT_EQ(s.x.length_bits, 24);
  EXPECT_TRUE(s.x.is_signed);
  EXPECT_DOUBLE_EQ(s.x.offset, 0.001);
  EXPECT_DOUBLE_EQ(s.temperature.offset, -40.0);
  EXPECT_DOUBLE_EQ(s.temperature.stale_timeout_s, 0.2);
  EXPECT_FALSE(s.command.send_each_cycle);
}

TEST(KeysCan, OverlapNamesKeyAndLine) {
  const std::string e = error_of(
      "can:\n"
      "  xdot:\n"
      "    present: true\n"
      "    start_bit: 8\n");
  EXPECT_NE(e.find("test.yaml:4"), std::string::npos) << e;
  EXPECT_NE(e.find("start_bit"), std::string::npos) << e;
  EXPECT_NE(e.find("signals x and xdot share bits in frame 0x101"), std::string::npos) << e;
}

TEST(KeysCan, TheHeaterCurrentIsOptionalAndItsBitsAreChecked) {
  EXPECT_FALSE(load("can: {}\n").current.present);
  const CanSettings s = load(
      "can:\n"
      "  current: {present: true, frame_id: 0x103, start_bit: 0, length_bits: 16, signed: true,\n"
      "            scale: 0.0001}\n");
  EXPECT_TRUE(s.current.present);
  EXPECT_EQ(s.current.frame_id, 0x103U);
  EXPECT_DOUBLE_EQ(s.current.scale, 1e-4);
  // In frame 0x102 on the temperature's bits.
  const std::string e = error_of(
      "can:\n"
      "  current:\n"
      "    present: true\n"
      "    start_bit: 16\n");
  EXPECT_NE(e.find("test.yaml:4"), std::string::npos) << e;
  EXPECT_NE(e.find("signals temperature and current share bits in frame 0x102"), std::string::npos)
      << e;
}

TEST(KeysCan, CommandIdClashNamesTheSensorKey) {
  const std::string e = error_of(
      "can:\n"
      "  x:\n"
      "    frame_id: 0x201\n");
  EXPECT_NE(e.find("test.yaml:3"), std::string::npos) << e;
  EXPECT_NE(e.find("is also the command frame id"), std::string::npos) << e;
}

TEST(KeysCan, SignalOutsideFrameAndIdRange) {
  std::string e = error_of("can:\n  temperature: {start_bit: 40}\n");
  EXPECT_NE(e.find("does not fit a frame of 8 bytes"), std::string::npos) << e;
  e = error_of("can:\n  x: {frame_id: 0x7FF0}\n");
  EXPECT_NE(e.find("does not fit 11 bits"), std::string::npos) << e;
  e = error_of("can:\n  x: {byte_order: middle_endian}\n");
  EXPECT_NE(e.find("byte_order"), std::string::npos) << e;
  e = error_of("can:\n  x: {start_bits: 3}\n");
  EXPECT_NE(e.find("unknown key"), std::string::npos) << e;
}

TEST(KeysCan, HeartbeatIsReadAndOffByDefault) {
  EXPECT_FALSE(load("can: {}\n").heartbeat.enabled);
  const CanSettings s = load(
      "can:\n"
      "  heartbeat: {enabled: true, frame_id: 0x701, period_ms: 50, payload: canopen}\n");
  EXPECT_TRUE(s.heartbeat.enabled);
  EXPECT_EQ(s.heartbeat.frame_id, 0x701U);
  EXPECT_DOUBLE_EQ(s.heartbeat.period_ms, 50.0);
  EXPECT_EQ(s.heartbeat.payload, drivers::can::HeartbeatPayload::canopen);
}

TEST(KeysCan, HeartbeatMistakesNameTheKeyAndLine) {
  std::string e = error_of(
      "can:\n"
      "  heartbeat:\n"
      "    enabled: true\n"
      "    frame_id: 0x800\n");
  EXPECT_NE(e.find("test.yaml:4"), std::string::npos) << e;
  EXPECT_NE(e.find("frame_id"), std::string::npos) << e;
  EXPECT_NE(e.find("does not fit 11 bits"), std::string::npos) << e;
  // The same id is fine as a 29-bit one.
  EXPECT_EQ(load("can:\n  heartbeat: {enabled: true, frame_id: 0x800, extended: true}\n")
                .heartbeat.frame_id,
            0x800U);
  e = error_of("can:\n  heartbeat:\n    period_ms: 0\n");
  EXPECT_NE(e.find("test.yaml:3"), std::string::npos) << e;
  EXPECT_NE(e.find("period_ms must lie in (0, 65535]"), std::string::npos) << e;
  e = error_of("can:\n  heartbeat:\n    enabled: true\n    frame_id: 0x201\n");
  EXPECT_NE(e.find("test.yaml:4"), std::string::npos) << e;
  EXPECT_NE(e.find("is also the command frame id"), std::string::npos) << e;
  e = error_of("can:\n  heartbeat: {enabled: true, frame_id: 0x102}\n");
  EXPECT_NE(e.find("frame of signal temperature"), std::string::npos) << e;
  e = error_of("can:\n  heartbeat: {payload: toggle}\n");
  EXPECT_NE(e.find("payload"), std::string::npos) << e;
}

TEST(KeysCan, DocumentingListsEveryKey) {
  Binder root = Binder::documenting();
  Binder can = root.section("can", "CAN driver");
  CanSettings out;
  declare_can_keys(can, out);
  bool found = false;
  bool heartbeat = false;
  for (const auto& d : root.docs()) {
    found = found || d.path == "can.command.send_each_cycle";
    heartbeat = heartbeat || d.path == "can.heartbeat.period_ms";
  }
  EXPECT_TRUE(found);
  EXPECT_TRUE(heartbeat);
}

}  // namespace
}  // namespace scp::config

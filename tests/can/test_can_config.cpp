// Config validation of the CAN driver: every layout mistake is refused with a message naming
// the key (and, through the Binder, the line).

#include <gtest/gtest.h>

#include <string>

#include "drivers/can/can_driver.hpp"
#include "drivers/can/can_settings.hpp"

namespace scp::drivers::can {
namespace {

std::string problem_key(const CanSettings& s) {
  const auto p = validate_can_settings(s);
  return p ? p->key + ": " + p->message : "";
}

TEST(CanSettingsValidation, DefaultIsValid) {
  EXPECT_EQ(problem_key(default_can_settings()), "");
  CanSettings s = default_can_settings();
  s.xdot.present = s.voltage.present = true;
  EXPECT_EQ(problem_key(s), "");
}

TEST(CanSettingsValidation, OverlappingSignalsInOneFrame) {
  CanSettings s = default_can_settings();
  s.xdot.present = true;
  s.xdot.start_bit = 16;  // x occupies bits 0..31
  const std::string p = problem_key(s);
  EXPECT_EQ(p.rfind("xdot.start_bit: signals x and xdot share bits in frame 0x101", 0), 0U) << p;
  // Same bits in a different frame are fine.
  s.xdot.frame_id = 0x103;
  EXPECT_EQ(problem_key(s), "");
}

TEST(CanSettingsValidation, SignalsOfOneFrameMustAgreeOnItsLength) {
  CanSettings s = default_can_settings();
  s.xdot.present = true;
  s.xdot.dlc = 6;
  s.xdot.start_bit = 32;
  s.xdot.length_bits = 16;
  const std::string p = problem_key(s);
  EXPECT_EQ(p.rfind("xdot.dlc: frame 0x101 is given 6 bytes here but 8 bytes for signal x", 0), 0U)
      << p;
}

TEST(CanSettingsValidation, SignalMustFitItsFrame) {
  CanSettings s = default_can_settings();
  s.x.start_bit = 40;  // 40 + 32 > 64
  std::string p = problem_key(s);
  EXPECT_EQ(p.rfind("x.start_bit: signal (start_bit 40, length_bits 32", 0), 0U) << p;
  EXPECT_NE(p.find("does not fit a frame of 8 bytes"), std::string::npos) << p;
  s = default_can_settings();
  s.temperature.dlc = 3;  // 32-bit temperature in 3 bytes
  p = problem_key(s);
  EXPECT_EQ(p.rfind("temperature.start_bit:", 0), 0U) << p;
  s = default_can_settings();
  s.command.signal.byte_order = ByteOrder::big_endian;  // MSB at bit 0 runs past byte 1
  s.command.signal.start_bit = 0;
  p = problem_key(s);
  EXPECT_EQ(p.rfind("command.start_bit:", 0), 0U) << p;
}

TEST(CanSettingsValidation, ClassicFramesHaveAtMostEightBytes) {
  CanSettings s = default_can_settings();
  s.x.dlc = 16;
  std::string p = problem_key(s);
  EXPECT_EQ(p.rfind("x.dlc: frame length 16 exceeds 8 bytes; set fd: true", 0), 0U) << p;
  s.fd = true;
  s.x.dlc = 13;
  p = problem_key(s);
  EXPECT_EQ(p.rfind("x.dlc: frame length 13 is not a CAN FD length", 0), 0U) << p;
  s.x.dlc = 64;
  s.x.start_bit = 480;
  EXPECT_EQ(problem_key(s), "");
}

TEST(CanSettingsValidation, CommandIdMustDifferFromSensorIds) {
  CanSettings s = default_can_settings();
  s.command.signal.frame_id = 0x102;
  const std::string p = problem_key(s);
  EXPECT_EQ(p.rfind("temperature.frame_id: frame id 0x102 is also the command frame id", 0), 0U)
      << p;
  // The same number as a 29-bit id is a different frame.
  s.command.signal.extended = true;
  EXPECT_EQ(problem_key(s), "");
}

TEST(CanSettingsValidation, IdRange) {
  CanSettings s = default_can_settings();
  s.x.frame_id = 0x800;
  std::string p = problem_key(s);
  EXPECT_EQ(p.rfind("x.frame_id: frame id 0x800 does not fit 11 bits (maximum 0x7FF); set "
                    "extended: true",
                    0),
            0U)
      << p;
  s.x.extended = true;
  EXPECT_EQ(problem_key(s), "");
  s.x.frame_id = 0x20000000;
  p = problem_key(s);
  EXPECT_EQ(p.rfind("x.frame_id: frame id 0x20000000 does not fit 29 bits", 0), 0U) << p;
}

TEST(CanSettingsValidation, RequiredSignalsAndScale) {
  CanSettings s = default_can_settings();
  s.temperature.present = false;
  EXPECT_EQ(problem_key(s).rfind("temperature.present:", 0), 0U);
  s = default_can_settings();
  s.x.scale = 0.0;
  EXPECT_EQ(problem_key(s).rfind("x.scale: scale must be finite and non-zero", 0), 0U);
  s = default_can_settings();
  s.interface = "";
  EXPECT_EQ(problem_key(s).rfind("interface:", 0), 0U);
}

TEST(CanSettingsValidation, DriverConstructorRefusesWithTheKey) {
  CanSettings s = default_can_settings();
  s.command.signal.frame_id = 0x101;
  try {
    CanDriver d(s);
    FAIL() << "accepted a command id equal to a sensor id";
  } catch (const DriverError& e) {
    EXPECT_EQ(std::string(e.what()).rfind("can.x.frame_id: frame id 0x101 is also the command", 0),
              0U)
        << e.what();
  }
}

}  // namespace
}  // namespace scp::drivers::can

// Against a real virtual CAN bus (vcan0), where the kernel has one. Set it up with
//   sudo modprobe vcan && sudo ip link add dev vcan0 type vcan && sudo ip link set vcan0 up

#include <gtest/gtest.h>

#include <string>

#include "drivers/can/can_channel.hpp"
#include "drivers/can/can_driver.hpp"
#include "drivers/can/signal_codec.hpp"

namespace scp::drivers::can {
namespace {

TEST(CanVcan, DriverTalksToANodeOverVcan0) {
  CanSettings s = default_can_settings();
  s.interface = "vcan0";
  CanDriver driver(s);
  try {
    driver.open();
  } catch (const DriverError& e) {
    const std::string why = e.what();
    // The message must tell the user what to do.
    EXPECT_TRUE(why.find("modprobe") != std::string::npos ||
                why.find("ip link") != std::string::npos)
        << why;
    GTEST_SKIP() << "no usable vcan0 on this machine (" << why << ")";
  }
  // The "device": a second socket on the same bus that sends x and temperature frames.
  const canid_t ids[1] = {s.command.signal.frame_id};
  CanChannel device = open_socketcan("vcan0", ids, false);
  canfd_frame x{}, t{};
  x.can_id = s.x.frame_id;
  x.len = 8;
  ASSERT_TRUE(encode_signal(s.x, -1.5e-3, x.data, 8));
  t.can_id = s.temperature.frame_id;
  t.len = 8;
  ASSERT_TRUE(encode_signal(s.temperature, 31.25, t.data, 8));
  ASSERT_EQ(device.send(x, false), TxStatus::sent);
  ASSERT_EQ(device.send(t, false), TxStatus::sent);
  Sample out;
  IoResult r;
  for (int i = 0; i < 100; ++i) {  // vcan delivers at once; allow a little scheduling
    r = driver.read(CycleTime{i * 1e-3, 1e-3}, out);
    if (r.status == IoStatus::ok) break;
  }
  ASSERT_EQ(r.status, IoStatus::ok) << r.reason;
  EXPECT_NEAR(out.x, -1.5e-3, 1e-9);
  EXPECT_NEAR(out.temperature, 31.25, 1e-4);
  ASSERT_EQ(driver.write_voltage(2.5).status, IoStatus::ok);
  canfd_frame cmd{};
  bool is_fd = false;
  RxStatus rx = RxStatus::empty;
  for (int i = 0; i < 1000 && rx != RxStatus::frame; ++i) rx = device.receive(cmd, is_fd);
  ASSERT_EQ(rx, RxStatus::frame);
  // The first command frame is open()'s 0 V; read until the 2.5 V one.
  if (decode_signal(s.command.signal, cmd.data, cmd.len) == 0.0) {
    rx = RxStatus::empty;
    for (int i = 0; i < 1000 && rx != RxStatus::frame; ++i) rx = device.receive(cmd, is_fd);
  }
  EXPECT_NEAR(decode_signal(s.command.signal, cmd.data, cmd.len), 2.5, 1e-9);
}

TEST(CanVcan, MissingInterfaceNamesTheRemedy) {
  const canid_t ids[1] = {0x101};
  try {
    (void)open_socketcan("nosuchcan7", ids, false);
    FAIL() << "opened a non-existent interface";
  } catch (const DriverError& e) {
    const std::string why = e.what();
    EXPECT_TRUE(why.find("modprobe") != std::string::npos ||
                why.find("ip link") != std::string::npos)
        << why;
  }
}

}  // namespace
}  // namespace scp::drivers::can

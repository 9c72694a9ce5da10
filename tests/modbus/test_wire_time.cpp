// The RTU wire model the driver stamps with (drivers/modbus/wire_time.hpp) and the line
// scp-simdaq --wire emulates (tools/simdaq/emulated_wire.hpp), checked against the Modbus
// serial line specification's arithmetic done by hand.
#include <gtest/gtest.h>

#include "drivers/modbus/wire_time.hpp"
#include "tools/simdaq/emulated_wire.hpp"

namespace scp::drivers::modbus {
namespace {

ModbusSettings rtu(int baud, char parity, int stop_bits) {
  ModbusSettings s;
  s.transport = Transport::rtu;
  s.baud = baud;
  s.parity = parity;
  s.stop_bits = stop_bits;
  return s;
}

TEST(WireTime, CharacterTimeCountsStartDataParityAndStopBits) {
  EXPECT_DOUBLE_EQ(char_time_s(rtu(115200, 'E', 1)), 11.0 / 115200);
  EXPECT_DOUBLE_EQ(char_time_s(rtu(115200, 'N', 2)), 11.0 / 115200);
  EXPECT_DOUBLE_EQ(char_time_s(rtu(115200, 'N', 1)), 10.0 / 115200);
  EXPECT_DOUBLE_EQ(char_time_s(rtu(19200, 'E', 1)), 11.0 / 19200);
  ModbusSettings tcp;
  tcp.transport = Transport::tcp;
  EXPECT_EQ(char_time_s(tcp), 0.0);
  EXPECT_EQ(event_after_midpoint_s(tcp, 8, 21), 0.0);
  // Through a TCP-to-RTU gateway the line behind it sets the times.
  ModbusSettings gateway = rtu(115200, 'E', 1);
  gateway.transport = Transport::tcp;
  gateway.timing.serial_line = true;
  EXPECT_DOUBLE_EQ(char_time_s(gateway), 11.0 / 115200);
  EXPECT_DOUBLE_EQ(event_after_midpoint_s(gateway, 8, 21),
                   event_after_midpoint_s(rtu(115200, 'E', 1), 8, 21));
}

TEST(WireTime, ReadSamplesBeforeAndWriteLandsAfterTheMidpoint) {
  const ModbusSettings s = rtu(115200, 'E', 1);
  const double c = 11.0 / 115200;
  // Read of 8 registers: request 8, reply 5 + 16 = 21 characters.
  EXPECT_EQ(read_reply_chars(8), 21);
  EXPECT_NEAR(event_after_midpoint_s(s, read_request_chars(), read_reply_chars(8)),
              0.5 * (8 + 3.5 - 21) * c, 1e-15);
  EXPECT_LT(event_after_midpoint_s(s, read_request_chars(), read_reply_chars(8)), -4e-4);
  // float32 command, function 16: 9 + 4 = 13 characters, echo of 8.
  EXPECT_EQ(write_request_chars(2), 13);
  EXPECT_EQ(write_request_chars(1), 8);  // function 6
  EXPECT_NEAR(event_after_midpoint_s(s, write_request_chars(2), write_reply_chars()),
              0.5 * (13 + 3.5 - 8) * c, 1e-15);
}

TEST(EmulatedWire, ActsAfterTheRequestAndTheGapAndHoldsTheLine) {
  const double c = 11.0 / 115200;
  simdaq::WireSettings ws;
  ws.char_s = c;
  ws.gap_s = 3.5 * c;
  simdaq::EmulatedWire wire(ws);
  const std::int64_t t0 = 1'000'000'000;
  const auto ns = [](double s) { return static_cast<std::int64_t>(std::llround(s * 1e9)); };
  const simdaq::WireTransaction a = wire.schedule(t0, 8, 21);
  EXPECT_EQ(a.event_ns, t0 + ns((8 + 3.5) * c));
  EXPECT_EQ(a.reply_ns, a.event_ns + ns(21 * c));
  // A request handed over before the line's trailing silence ends waits for it.
  const simdaq::WireTransaction b = wire.schedule(a.reply_ns, 13, 8);
  EXPECT_EQ(b.event_ns, a.reply_ns + ns(3.5 * c) + ns((13 + 3.5) * c));
  // The midpoint model: the event is (R + 3.5 − Q)/2 characters from the transaction's middle.
  ModbusSettings s = rtu(115200, 'E', 1);
  const double mid = 0.5 * static_cast<double>(t0 + a.reply_ns) * 1e-9;
  EXPECT_NEAR(static_cast<double>(a.event_ns) * 1e-9 - mid, event_after_midpoint_s(s, 8, 21), 2e-9);

  ws.jitter_s = 2e-4;
  simdaq::EmulatedWire jittery(ws);
  for (int i = 0; i < 100; ++i) {
    const std::int64_t at = t0 + i * 10'000'000LL;
    const simdaq::WireTransaction j = jittery.schedule(at, 8, 21);
    EXPECT_GE(j.event_ns, at + ns((8 + 3.5) * c));
    EXPECT_LE(j.event_ns, at + ns((8 + 3.5) * c + 2e-4) + 1);
    EXPECT_GE(j.reply_ns - j.event_ns, ns(21 * c));
    EXPECT_LE(j.reply_ns - j.event_ns, ns(21 * c + 2e-4) + 1);
  }
}

}  // namespace
}  // namespace scp::drivers::modbus

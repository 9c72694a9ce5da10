// Register encodings checked against values worked out by hand from IEEE 754 and two's
// complement, not against the codec's own output.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>

#include "drivers/modbus/register_codec.hpp"

namespace scp::drivers::modbus {
namespace {

RegisterSignal sig(RegisterType type, WordOrder order, double scale = 1.0, double offset = 0.0) {
  RegisterSignal s;
  s.present = true;
  s.type = type;
  s.word_order = order;
  s.scale = scale;
  s.offset = offset;
  return s;
}

using Regs = std::array<std::uint16_t, 2>;

TEST(RegisterCodec, Float32OnePointFiveBothWordOrders) {
  // 1.5f = sign 0, exponent 127 (0x7F), mantissa 0x400000 -> 0x3FC00000.
  Regs ab{0x3FC0, 0x0000}, ba{0x0000, 0x3FC0};
  EXPECT_EQ(decode_register_signal(sig(RegisterType::float32, WordOrder::ab), ab.data()), 1.5);
  EXPECT_EQ(decode_register_signal(sig(RegisterType::float32, WordOrder::ba), ba.data()), 1.5);
  Regs out{};
  ASSERT_TRUE(encode_value(RegisterType::float32, WordOrder::ab, 1, 0, 1.5, out.data()));
  EXPECT_EQ(out, ab);
  ASSERT_TRUE(encode_value(RegisterType::float32, WordOrder::ba, 1, 0, 1.5, out.data()));
  EXPECT_EQ(out, ba);
  // The wrong word order gives a denormal, not an error: why word_order is mandatory.
  EXPECT_LT(std::fabs(decode_register_signal(sig(RegisterType::float32, WordOrder::ba), ab.data())),
            1e-37);
}

TEST(RegisterCodec, Float32NegativeAndNaNPassThrough) {
  Regs minus25{0xC1C8, 0x0000};  // -25.0f = 0xC1C80000
  EXPECT_EQ(decode_register_signal(sig(RegisterType::float32, WordOrder::ab), minus25.data()),
            -25.0);
  Regs nan{0x7FC0, 0x0000};
  EXPECT_TRUE(
      std::isnan(decode_register_signal(sig(RegisterType::float32, WordOrder::ab), nan.data())));
  Regs inf{0x7F80, 0x0000};
  EXPECT_TRUE(
      std::isinf(decode_register_signal(sig(RegisterType::float32, WordOrder::ab), inf.data())));
}

TEST(RegisterCodec, Int32AndUint32WordOrders) {
  Regs minus2_ab{0xFFFF, 0xFFFE}, minus2_ba{0xFFFE, 0xFFFF};
  EXPECT_EQ(decode_register_signal(sig(RegisterType::int32, WordOrder::ab), minus2_ab.data()),
            -2.0);
  EXPECT_EQ(decode_register_signal(sig(RegisterType::int32, WordOrder::ba), minus2_ba.data()),
            -2.0);
  Regs u{0x1234, 0x5678};
  EXPECT_EQ(decode_register_signal(sig(RegisterType::uint32, WordOrder::ab), u.data()),
            305419896.0);
  EXPECT_EQ(decode_register_signal(sig(RegisterType::uint32, WordOrder::ba), u.data()),
            static_cast<double>(0x56781234u));
  // int32 -1250 µm with scale 1e-6 -> -1.25 mm; -1250 = 0xFFFFFB1E.
  Regs x{0xFFFF, 0xFB1E};
  EXPECT_DOUBLE_EQ(decode_register_signal(sig(RegisterType::int32, WordOrder::ab, 1e-6), x.data()),
                   -0.00125);
  Regs out{};
  ASSERT_TRUE(encode_value(RegisterType::int32, WordOrder::ba, 1e-6, 0, -0.00125, out.data()));
  EXPECT_EQ(out, (Regs{0xFB1E, 0xFFFF}));
  ASSERT_TRUE(encode_value(RegisterType::uint32, WordOrder::ab, 1, 0, 4294967295.0, out.data()));
  EXPECT_EQ(out, (Regs{0xFFFF, 0xFFFF}));
  EXPECT_FALSE(encode_value(RegisterType::uint32, WordOrder::ab, 1, 0, 4294967296.0, out.data()));
  EXPECT_FALSE(encode_value(RegisterType::int32, WordOrder::ab, 1, 0, -2147483649.0, out.data()));
}

TEST(RegisterCodec, SixteenBitScaleOffsetAndRange) {
  Regs r{0xFFFF, 0};
  EXPECT_DOUBLE_EQ(
      decode_register_signal(sig(RegisterType::int16, WordOrder::none, 0.01), r.data()), -0.01);
  EXPECT_DOUBLE_EQ(
      decode_register_signal(sig(RegisterType::uint16, WordOrder::none, 0.1, -10.0), r.data()),
      6543.5);  // 65535 * 0.1 - 10
  Regs out{};
  // raw = (1.26 - 0) / 0.1 = 12.6 -> rounds to 13.
  ASSERT_TRUE(encode_value(RegisterType::uint16, WordOrder::none, 0.1, 0, 1.26, out.data()));
  EXPECT_EQ(out[0], 13);
  // raw = (V - offset)/scale = (2.5 - (-10)) / 0.001 = 12500.
  ASSERT_TRUE(encode_value(RegisterType::int16, WordOrder::none, 0.001, -10, 2.5, out.data()));
  EXPECT_EQ(out[0], 12500);
  ASSERT_TRUE(encode_value(RegisterType::int16, WordOrder::none, 1, 0, -32768, out.data()));
  EXPECT_EQ(out[0], 0x8000);
  EXPECT_FALSE(encode_value(RegisterType::int16, WordOrder::none, 1, 0, 32768, out.data()));
  EXPECT_FALSE(encode_value(RegisterType::uint16, WordOrder::none, 1, 0, -1, out.data()));
  EXPECT_FALSE(encode_value(RegisterType::uint16, WordOrder::none, 1, 0, NAN, out.data()));
  EXPECT_FALSE(encode_value(RegisterType::float32, WordOrder::ab, 1, 0, 1e39, out.data()));
  EXPECT_FALSE(encode_value(RegisterType::uint16, WordOrder::none, 0.0, 0, 1, out.data()));
}

}  // namespace
}  // namespace scp::drivers::modbus

// DBC signal codec against hand-made frames (cantools / Vector conventions: Intel start bit =
// LSB, Motorola start bit = MSB, bit 7 of byte 0 is bit number 7).

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <random>

#include "drivers/can/signal_codec.hpp"

namespace scp::drivers::can {
namespace {

CanSignal sig(int start, int length, ByteOrder order, bool is_signed = false, double scale = 1.0,
              double offset = 0.0) {
  CanSignal s;
  s.present = true;
  s.start_bit = start;
  s.length_bits = length;
  s.byte_order = order;
  s.is_signed = is_signed;
  s.scale = scale;
  s.offset = offset;
  return s;
}

constexpr auto kIntel = ByteOrder::little_endian;
constexpr auto kMotorola = ByteOrder::big_endian;

TEST(SignalCodec, IntelByteAligned16) {
  const std::uint8_t d[8] = {0x34, 0x12, 0, 0, 0, 0, 0, 0};  // SG_ S : 0|16@1+
  EXPECT_EQ(extract_raw(sig(0, 16, kIntel), d, 8), 0x1234U);
  EXPECT_DOUBLE_EQ(decode_signal(sig(0, 16, kIntel), d, 8), 4660.0);
}

TEST(SignalCodec, IntelCrossesByteBoundary) {
  // SG_ S : 4|8@1+ : low nibble of the value in bits 4..7 of byte 0, high nibble in byte 1.
  const std::uint8_t d[2] = {0xA0, 0x0B};
  EXPECT_EQ(extract_raw(sig(4, 8, kIntel), d, 2), 0xBAU);
}

TEST(SignalCodec, MotorolaByteAligned16) {
  const std::uint8_t d[8] = {0x12, 0x34, 0, 0, 0, 0, 0, 0};  // SG_ S : 7|16@0+
  EXPECT_EQ(extract_raw(sig(7, 16, kMotorola), d, 8), 0x1234U);
}

TEST(SignalCodec, MotorolaCrossesByteBoundary) {
  // SG_ S : 3|8@0+ : MSB at bit 3 of byte 0, bits 3..0 then bits 7..4 of byte 1.
  const std::uint8_t d[2] = {0x0A, 0xB0};
  EXPECT_EQ(extract_raw(sig(3, 8, kMotorola), d, 2), 0xABU);
  // SG_ S : 0|2@0+ : bit 0 of byte 0 is the MSB, bit 7 of byte 1 the LSB.
  const std::uint8_t e[2] = {0x01, 0x00};
  EXPECT_EQ(extract_raw(sig(0, 2, kMotorola), e, 2), 0x2U);
  EXPECT_FALSE(signal_fits(sig(0, 2, kMotorola), 1));
}

TEST(SignalCodec, Motorola32) {
  // SG_ S : 7|32@0- : big-endian int32 in bytes 0..3.
  const std::uint8_t d[4] = {0xFF, 0xFF, 0xFE, 0x0C};  // -500
  EXPECT_DOUBLE_EQ(decode_signal(sig(7, 32, kMotorola, true), d, 4), -500.0);
}

TEST(SignalCodec, SignedScaleOffset) {
  // SG_ S : 0|12@1- (0.5,10) with raw 0xFFF = -1 → 9.5.
  const std::uint8_t d[2] = {0xFF, 0x0F};
  EXPECT_DOUBLE_EQ(decode_signal(sig(0, 12, kIntel, true, 0.5, 10.0), d, 2), 9.5);
  // Raw 0x800 is the most negative 12-bit value, -2048 → -1014.
  const std::uint8_t e[2] = {0x00, 0x08};
  EXPECT_DOUBLE_EQ(decode_signal(sig(0, 12, kIntel, true, 0.5, 10.0), e, 2), -1014.0);
  // The same bits unsigned: 2048 · 0.5 + 10.
  EXPECT_DOUBLE_EQ(decode_signal(sig(0, 12, kIntel, false, 0.5, 10.0), e, 2), 1034.0);
}

TEST(SignalCodec, AllOnesIsReportedAsItIs) {
  // A DAQ's "not available" pattern decodes to its (absurd) physical value; the safety layer
  // rejects it, not the codec.
  const std::uint8_t d[8] = {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF};
  EXPECT_DOUBLE_EQ(decode_signal(sig(0, 16, kIntel, false, 0.01), d, 8), 655.35);
  EXPECT_DOUBLE_EQ(decode_signal(sig(0, 64, kIntel), d, 8), 18446744073709551615.0);
  EXPECT_DOUBLE_EQ(decode_signal(sig(0, 64, kIntel, true), d, 8), -1.0);
}

TEST(SignalCodec, EncodeMatchesHandMadeFrames) {
  std::uint8_t d[8] = {};
  ASSERT_TRUE(encode_signal(sig(7, 16, kMotorola), 0x1234, d, 8));
  EXPECT_EQ(d[0], 0x12);
  EXPECT_EQ(d[1], 0x34);
  std::uint8_t e[2] = {0xAA, 0xAA};
  ASSERT_TRUE(encode_signal(sig(4, 8, kIntel), 0xBB, e, 2));
  EXPECT_EQ(e[0], 0xBA);  // bits 0..3 untouched
  EXPECT_EQ(e[1], 0xAB);  // bits 4..7 untouched
  std::uint8_t f[2] = {};
  ASSERT_TRUE(encode_signal(sig(0, 12, kIntel, true, 0.5, 10.0), 9.5, f, 2));
  EXPECT_EQ(f[0], 0xFF);
  EXPECT_EQ(f[1], 0x0F);
  // 1.2345 V at 1 mV per bit rounds to 1235 = 0x04D3.
  std::uint8_t g[2] = {};
  ASSERT_TRUE(encode_signal(sig(0, 16, kIntel, false, 1e-3), 1.2345, g, 2));
  EXPECT_EQ(g[0], 0xD3);
  EXPECT_EQ(g[1], 0x04);
}

TEST(SignalCodec, EncodeSaturatesAndRefusesNonFinite) {
  std::uint8_t d[2] = {0x11, 0x22};
  EXPECT_FALSE(encode_signal(sig(0, 16, kIntel), std::nan(""), d, 2));
  EXPECT_FALSE(encode_signal(sig(0, 16, kIntel), INFINITY, d, 2));
  EXPECT_EQ(d[0], 0x11);
  ASSERT_TRUE(encode_signal(sig(0, 16, kIntel, false, 1e-3), 100.0, d, 2));
  EXPECT_EQ(d[0], 0xFF);
  EXPECT_EQ(d[1], 0xFF);
  ASSERT_TRUE(encode_signal(sig(0, 16, kIntel, false, 1e-3), -5.0, d, 2));
  EXPECT_EQ(d[0], 0x00);
  EXPECT_EQ(d[1], 0x00);
  ASSERT_TRUE(encode_signal(sig(0, 8, kIntel, true), -1000.0, d, 2));
  EXPECT_EQ(d[0], 0x80);
  ASSERT_TRUE(encode_signal(sig(0, 8, kIntel, true), 1000.0, d, 2));
  EXPECT_EQ(d[0], 0x7F);
}

TEST(SignalCodec, FitRules) {
  EXPECT_TRUE(signal_fits(sig(0, 64, kIntel), 8));
  EXPECT_FALSE(signal_fits(sig(60, 8, kIntel), 8));  // start + length > 64
  EXPECT_TRUE(signal_fits(sig(7, 64, kMotorola), 8));
  EXPECT_FALSE(signal_fits(sig(6, 64, kMotorola), 8));  // runs one bit into byte 8
  EXPECT_TRUE(signal_fits(sig(504, 8, kIntel), 64));    // last byte of an FD frame
  EXPECT_FALSE(signal_fits(sig(0, 0, kIntel), 8));
  EXPECT_FALSE(signal_fits(sig(0, 65, kIntel), 16));
  EXPECT_TRUE(std::isnan(decode_signal(sig(0, 16, kIntel), nullptr, 8)));
  const std::uint8_t d[1] = {0};
  EXPECT_TRUE(std::isnan(decode_signal(sig(0, 16, kIntel), d, 1)));
}

TEST(SignalCodec, Overlap) {
  EXPECT_FALSE(signals_overlap(sig(0, 16, kIntel), sig(16, 16, kIntel)));
  EXPECT_TRUE(signals_overlap(sig(0, 17, kIntel), sig(16, 16, kIntel)));
  // Motorola 7|16 occupies bytes 0-1; Intel 8|8 is byte 1.
  EXPECT_TRUE(signals_overlap(sig(7, 16, kMotorola), sig(8, 8, kIntel)));
  EXPECT_FALSE(signals_overlap(sig(7, 16, kMotorola), sig(16, 8, kIntel)));
}

// Random layouts and payloads: never out of bounds (run under ASan), insert/extract agree and
// bits outside the signal are untouched.
TEST(SignalCodec, FuzzRoundTripAndNeighbours) {
  std::mt19937_64 rng(42);
  for (int trial = 0; trial < 20000; ++trial) {
    const std::size_t dlc = rng() % 65;
    CanSignal s = sig(static_cast<int>(rng() % 520), 1 + static_cast<int>(rng() % 64),
                      (rng() & 1) ? kIntel : kMotorola, (rng() & 1) != 0);
    std::uint8_t d[64];
    for (auto& b : d) b = static_cast<std::uint8_t>(rng());
    std::uint8_t before[64];
    std::copy(std::begin(d), std::end(d), std::begin(before));
    const std::uint64_t mask =
        s.length_bits == 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << s.length_bits) - 1;
    const std::uint64_t raw = rng() & mask;
    const bool fits = signal_fits(s, dlc);
    EXPECT_EQ(insert_raw(s, raw, d, dlc), fits);
    if (!fits) {
      EXPECT_TRUE(std::equal(std::begin(d), std::end(d), std::begin(before)));
      continue;
    }
    EXPECT_EQ(extract_raw(s, d, dlc), raw);
    // Clearing the signal in both copies must leave them equal: nothing else changed.
    (void)insert_raw(s, 0, d, dlc);
    (void)insert_raw(s, 0, before, dlc);
    EXPECT_TRUE(std::equal(std::begin(d), std::end(d), std::begin(before)));
  }
}

}  // namespace
}  // namespace scp::drivers::can

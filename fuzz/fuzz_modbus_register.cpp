// Fuzzes the Modbus register codec with fuzzed types, word orders, scales and register words.
// Properties checked against the definition of each type (two's complement, IEEE-754 binary32,
// word order), not against the codec's own output:
//  - int16/uint16 and int32/uint32 decode inside their type's range;
//  - with scale 1 and offset 0, encoding the decoded value of any finite pattern gives back the
//    same registers (a NaN/inf float32 is refused);
//  - encode_value refuses non-finite values and scales and leaves `out` untouched when it refuses.

#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "drivers/modbus/register_codec.hpp"
#include "fuzz/fuzz_check.hpp"

namespace mb = scp::drivers::modbus;

namespace {

template <typename T>
T take(const std::uint8_t*& data, std::size_t& size) {
  T value{};
  const std::size_t n = sizeof(T) < size ? sizeof(T) : size;
  std::memcpy(&value, data, n);
  data += n;
  size -= n;
  return value;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto selector = take<std::uint8_t>(data, size);
  const auto type = static_cast<mb::RegisterType>(selector % 5);
  const auto order = static_cast<mb::WordOrder>((selector / 5) % 3);
  const std::uint16_t regs[2] = {take<std::uint16_t>(data, size), take<std::uint16_t>(data, size)};
  const double scale = take<double>(data, size);
  const double offset = take<double>(data, size);
  const double value = take<double>(data, size);

  const double raw = mb::decode_raw(type, order, regs);
  const std::uint32_t hi = order == mb::WordOrder::ba ? regs[1] : regs[0];
  const std::uint32_t lo = order == mb::WordOrder::ba ? regs[0] : regs[1];
  const std::uint32_t word = (hi << 16) | lo;
  switch (type) {
    case mb::RegisterType::int16:
      FUZZ_CHECK(raw >= -32768.0 && raw <= 32767.0);
      FUZZ_CHECK(raw == (regs[0] < 0x8000 ? regs[0] : regs[0] - 65536.0));
      break;
    case mb::RegisterType::uint16:
      FUZZ_CHECK(raw == regs[0]);
      break;
    case mb::RegisterType::int32:
      FUZZ_CHECK(raw == (word < 0x80000000u ? word : word - 4294967296.0));
      break;
    case mb::RegisterType::uint32:
      FUZZ_CHECK(raw == word);
      break;
    case mb::RegisterType::float32: {
      // IEEE-754 binary32 by hand: sign, 8-bit biased exponent, 23-bit fraction.
      const int exponent = static_cast<int>((word >> 23) & 0xFFu);
      const double fraction = static_cast<double>(word & 0x7FFFFFu);
      const double sign = (word >> 31) ? -1.0 : 1.0;
      if (exponent == 255) {
        FUZZ_CHECK(fraction == 0.0 ? std::isinf(raw) && std::signbit(raw) == (sign < 0)
                                   : std::isnan(raw));
      } else if (exponent == 0) {
        FUZZ_CHECK(raw == sign * std::ldexp(fraction, -149));
      } else {
        FUZZ_CHECK(raw == sign * std::ldexp(fraction + 8388608.0, exponent - 150));
      }
      break;
    }
  }

  // Round trip with the identity scaling.
  const int count = mb::register_count(type);
  std::uint16_t out[2] = {0xDEAD, 0xBEEF};
  const bool ok = mb::encode_value(type, order, 1.0, 0.0, raw, out);
  FUZZ_CHECK(ok == std::isfinite(raw));
  if (ok) {
    FUZZ_CHECK(out[0] == regs[0]);
    if (count == 2) FUZZ_CHECK(out[1] == regs[1]);
  }

  // Arbitrary scaling: no UB, and the documented refusals.
  const mb::RegisterSignal signal{true, mb::Table::input, 0, type, order, scale, offset};
  static_cast<void>(mb::decode_register_signal(signal, regs));
  std::uint16_t out2[2] = {0x1234, 0x5678};
  const bool ok2 = mb::encode_value(type, order, scale, offset, value, out2);
  if (!std::isfinite(value) || !std::isfinite(scale) || scale == 0.0) FUZZ_CHECK(!ok2);
  if (!ok2) FUZZ_CHECK(out2[0] == 0x1234 && out2[1] == 0x5678);
  if (ok2 && count == 1) FUZZ_CHECK(out2[1] == 0x5678);
  return 0;
}

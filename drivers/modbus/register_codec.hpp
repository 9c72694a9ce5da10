#pragma once
// Conversion between 16-bit Modbus registers and engineering values. Pure, header-only and
// allocation-free, so the config checks (scp_config), the driver's real-time path and the
// simulated DAQ share one definition, and a fuzzer can call it directly.

#include <bit>
#include <cmath>
#include <cstdint>
#include <string_view>

#include "drivers/modbus/modbus_settings.hpp"

namespace scp::drivers::modbus {

constexpr int register_count(RegisterType type) noexcept {
  return (type == RegisterType::int16 || type == RegisterType::uint16) ? 1 : 2;
}

constexpr std::string_view type_name(RegisterType type) noexcept {
  switch (type) {
    case RegisterType::int16:
      return "int16";
    case RegisterType::uint16:
      return "uint16";
    case RegisterType::int32:
      return "int32";
    case RegisterType::uint32:
      return "uint32";
    case RegisterType::float32:
      return "float32";
  }
  return "?";
}

constexpr std::string_view table_name(Table table) noexcept {
  return table == Table::input ? "input" : "holding";
}

// The raw value of `type` held in regs[0..register_count(type)), before scale and offset.
inline double decode_raw(RegisterType type, WordOrder order, const std::uint16_t* regs) noexcept {
  const auto word32 = [&]() -> std::uint32_t {
    const std::uint32_t hi = order == WordOrder::ba ? regs[1] : regs[0];
    const std::uint32_t lo = order == WordOrder::ba ? regs[0] : regs[1];
    return (hi << 16) | lo;
  };
  switch (type) {
    case RegisterType::int16:
      return static_cast<std::int16_t>(regs[0]);
    case RegisterType::uint16:
      return regs[0];
    case RegisterType::int32:
      return static_cast<std::int32_t>(word32());
    case RegisterType::uint32:
      return word32();
    case RegisterType::float32:
      return std::bit_cast<float>(word32());
  }
  return std::nan("");
}

// Engineering value = raw · scale + offset. A float32 register may hold NaN or ±inf: the result is
// then non-finite and the loop's safety layer faults on it (the driver does not hide it).
inline double decode_register_signal(const RegisterSignal& signal,
                                     const std::uint16_t* regs) noexcept {
  return decode_raw(signal.type, signal.word_order, regs) * signal.scale + signal.offset;
}

// Writes `value` (engineering units) as raw = (value − offset) / scale into out[0..count).
// Integer types round to nearest. Returns false (out untouched) when the raw value is not finite
// or does not fit the type.
inline bool encode_value(RegisterType type, WordOrder order, double scale, double offset,
                         double value, std::uint16_t* out) noexcept {
  if (!std::isfinite(value) || !std::isfinite(scale) || scale == 0.0) return false;
  const double raw = (value - offset) / scale;
  if (!std::isfinite(raw)) return false;
  std::uint32_t word = 0;
  switch (type) {
    case RegisterType::int16:
    case RegisterType::uint16:
    case RegisterType::int32:
    case RegisterType::uint32: {
      const double r = std::nearbyint(raw);
      const double lo = type == RegisterType::int16   ? -32768.0
                        : type == RegisterType::int32 ? -2147483648.0
                                                      : 0.0;
      const double hi = type == RegisterType::int16    ? 32767.0
                        : type == RegisterType::uint16 ? 65535.0
                        : type == RegisterType::int32  ? 2147483647.0
                                                       : 4294967295.0;
      if (r < lo || r > hi) return false;
      if (type == RegisterType::int16 || type == RegisterType::int32) {
        word = static_cast<std::uint32_t>(static_cast<std::int64_t>(r));
      } else {
        word = static_cast<std::uint32_t>(r);
      }
      break;
    }
    case RegisterType::float32: {
      if (std::fabs(raw) > 3.4028234663852886e38) return false;
      word = std::bit_cast<std::uint32_t>(static_cast<float>(raw));
      break;
    }
  }
  if (register_count(type) == 1) {
    out[0] = static_cast<std::uint16_t>(word & 0xFFFFu);
    return true;
  }
  const auto hi = static_cast<std::uint16_t>(word >> 16);
  const auto lo = static_cast<std::uint16_t>(word & 0xFFFFu);
  out[0] = order == WordOrder::ba ? lo : hi;
  out[1] = order == WordOrder::ba ? hi : lo;
  return true;
}

inline bool encode_command(const CommandRegister& command, double volts,
                           std::uint16_t* out) noexcept {
  return encode_value(command.type, command.word_order, command.scale, command.offset, volts, out);
}

}  // namespace scp::drivers::modbus

#include "drivers/can/signal_codec.hpp"

#include <array>
#include <cmath>

namespace scp::drivers::can {
namespace {

bool layout_valid(const CanSignal& sig) noexcept {
  return sig.length_bits >= 1 && sig.length_bits <= 64 && sig.start_bit >= 0 &&
         sig.start_bit < static_cast<int>(8 * kMaxPayload);
}

// Calls f(position, significance) for every bit of the signal, where position = 8·byte + bit
// (bit 0 = least significant bit of the byte, the DBC numbering for both byte orders) and
// significance is the bit's weight in the raw value (0 = LSB).
template <typename F>
void for_each_bit(const CanSignal& sig, F&& f) noexcept {
  if (sig.byte_order == ByteOrder::little_endian) {
    // Intel: start_bit is the LSB; higher bits run upwards through the bytes.
    for (int i = 0; i < sig.length_bits; ++i) f(sig.start_bit + i, i);
  } else {
    // Motorola: start_bit is the MSB; lower bits run down within a byte, then continue at bit 7
    // of the next byte (the "sawtooth" of the DBC layout).
    int pos = sig.start_bit;
    for (int i = sig.length_bits - 1; i >= 0; --i) {
      f(pos, i);
      pos = (pos % 8 == 0) ? pos + 15 : pos - 1;
    }
  }
}

// Position of the last bit visited, to test the fit without touching data.
int highest_byte(const CanSignal& sig) noexcept {
  int top = 0;
  for_each_bit(sig, [&](int pos, int) {
    if (pos / 8 > top) top = pos / 8;
  });
  return top;
}

}  // namespace

bool signal_fits(const CanSignal& sig, std::size_t dlc) noexcept {
  if (!layout_valid(sig) || dlc > kMaxPayload) return false;
  return static_cast<std::size_t>(highest_byte(sig)) < dlc;
}

std::uint64_t extract_raw(const CanSignal& sig, const std::uint8_t* data,
                          std::size_t dlc) noexcept {
  if (data == nullptr || !signal_fits(sig, dlc)) return 0;
  std::uint64_t raw = 0;
  for_each_bit(sig, [&](int pos, int weight) {
    const std::uint64_t bit = (data[pos / 8] >> (pos % 8)) & 1U;
    raw |= bit << weight;
  });
  return raw;
}

bool insert_raw(const CanSignal& sig, std::uint64_t raw, std::uint8_t* data,
                std::size_t dlc) noexcept {
  if (data == nullptr || !signal_fits(sig, dlc)) return false;
  for_each_bit(sig, [&](int pos, int weight) {
    const auto mask = static_cast<std::uint8_t>(1U << (pos % 8));
    if ((raw >> weight) & 1U) {
      data[pos / 8] = static_cast<std::uint8_t>(data[pos / 8] | mask);
    } else {
      data[pos / 8] = static_cast<std::uint8_t>(data[pos / 8] & ~mask);
    }
  });
  return true;
}

double decode_signal(const CanSignal& sig, const std::uint8_t* data, std::size_t dlc) noexcept {
  if (data == nullptr || !signal_fits(sig, dlc)) return std::nan("");
  const std::uint64_t raw = extract_raw(sig, data, dlc);
  double value = 0.0;
  if (sig.is_signed && sig.length_bits < 64 && ((raw >> (sig.length_bits - 1)) & 1U)) {
    // Sign-extend: the raw pattern minus 2^length.
    const std::uint64_t extended = raw | (~std::uint64_t{0} << sig.length_bits);
    value = static_cast<double>(static_cast<std::int64_t>(extended));
  } else if (sig.is_signed) {
    value = static_cast<double>(static_cast<std::int64_t>(raw));
  } else {
    value = static_cast<double>(raw);
  }
  return value * sig.scale + sig.offset;
}

bool encode_signal(const CanSignal& sig, double value, std::uint8_t* data,
                   std::size_t dlc) noexcept {
  if (!std::isfinite(value) || !std::isfinite(sig.scale) || sig.scale == 0.0 ||
      !signal_fits(sig, dlc) || data == nullptr) {
    return false;
  }
  const double scaled = std::round((value - sig.offset) / sig.scale);
  if (!std::isfinite(scaled)) return false;
  const int n = sig.length_bits;
  // Raw range as doubles; 2^63 and 2^64 are exact in binary floating point.
  const double lo = sig.is_signed ? -std::ldexp(1.0, n - 1) : 0.0;
  const double hi_excl = sig.is_signed ? std::ldexp(1.0, n - 1) : std::ldexp(1.0, n);
  std::uint64_t raw = 0;
  if (scaled <= lo) {
    raw = sig.is_signed ? (std::uint64_t{1} << (n - 1)) : 0;  // most negative pattern
  } else if (scaled >= hi_excl) {
    raw = sig.is_signed ? ((std::uint64_t{1} << (n - 1)) - 1)
                        : (n == 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << n) - 1);
  } else if (scaled < 0.0) {
    raw = static_cast<std::uint64_t>(static_cast<std::int64_t>(scaled));  // two's complement
  } else {
    raw = static_cast<std::uint64_t>(scaled);
  }
  return insert_raw(sig, raw, data, dlc);
}

bool signals_overlap(const CanSignal& a, const CanSignal& b) noexcept {
  if (!layout_valid(a) || !layout_valid(b)) return false;
  std::array<bool, 8 * kMaxPayload> used{};
  for_each_bit(a, [&](int pos, int) {
    if (static_cast<std::size_t>(pos) < used.size()) used[static_cast<std::size_t>(pos)] = true;
  });
  bool overlap = false;
  for_each_bit(b, [&](int pos, int) {
    if (static_cast<std::size_t>(pos) < used.size() && used[static_cast<std::size_t>(pos)]) {
      overlap = true;
    }
  });
  return overlap;
}

}  // namespace scp::drivers::can

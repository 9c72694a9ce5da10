// Fuzzes the DBC signal codec with a fuzzed layout and payload. The payload is copied into a heap
// buffer of exactly `dlc` bytes so that AddressSanitizer sees any read or write past the frame.
// Properties checked against the definition of the layout, not against the codec's own output:
//  - a signal that does not fit decodes to NaN and is never written;
//  - re-inserting the extracted raw bits leaves the payload unchanged;
//  - inserting a raw value and extracting it gives back its low length_bits bits, and only the
//    signal's length_bits bits of the payload change.

#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>

#include "drivers/can/signal_codec.hpp"
#include "fuzz/fuzz_check.hpp"

namespace can = scp::drivers::can;

namespace {

// Consumes fixed-size fields from the front of the input; zeros once it runs out.
class Reader {
 public:
  Reader(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {}
  template <typename T>
  T take() {
    T value{};
    const std::size_t n = sizeof(T) < size_ ? sizeof(T) : size_;
    std::memcpy(&value, data_, n);
    data_ += n;
    size_ -= n;
    return value;
  }
  const std::uint8_t* data() const { return data_; }
  std::size_t size() const { return size_; }

 private:
  const std::uint8_t* data_;
  std::size_t size_;
};

int popcount_diff(const std::uint8_t* a, const std::uint8_t* b, std::size_t n) {
  int bits = 0;
  for (std::size_t i = 0; i < n; ++i) bits += std::popcount(static_cast<unsigned>(a[i] ^ b[i]));
  return bits;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Reader in(data, size);
  can::CanSignal sig;
  // Mostly plausible layouts (small numbers) but every int value is reachable.
  const auto mode = in.take<std::uint8_t>();
  if (mode & 1U) {
    sig.start_bit = in.take<std::int32_t>();
    sig.length_bits = in.take<std::int32_t>();
  } else {
    sig.start_bit = in.take<std::uint16_t>() % 600;
    sig.length_bits = in.take<std::uint8_t>() % 70;
  }
  sig.byte_order = (mode & 2U) ? can::ByteOrder::big_endian : can::ByteOrder::little_endian;
  sig.is_signed = (mode & 4U) != 0;
  sig.scale = (mode & 8U) ? in.take<double>() : 0.5;
  sig.offset = (mode & 16U) ? in.take<double>() : -3.0;
  const std::uint64_t raw_in = in.take<std::uint64_t>();
  const double value_in = in.take<double>();
  std::size_t dlc = in.take<std::uint8_t>();
  if (dlc > in.size()) dlc = in.size();
  sig.dlc = static_cast<int>(dlc);

  // Exactly dlc bytes on the heap (a 1-byte allocation for dlc = 0 keeps the pointer non-null).
  const std::unique_ptr<std::uint8_t[]> frame(new std::uint8_t[dlc == 0 ? 1 : dlc]);
  if (dlc > 0) std::memcpy(frame.get(), in.data(), dlc);
  const std::unique_ptr<std::uint8_t[]> copy(new std::uint8_t[dlc == 0 ? 1 : dlc]);
  if (dlc > 0) std::memcpy(copy.get(), frame.get(), dlc);

  const bool fits = can::signal_fits(sig, dlc);
  const double decoded = can::decode_signal(sig, frame.get(), dlc);
  if (!fits) {
    FUZZ_CHECK(std::isnan(decoded));
    FUZZ_CHECK(can::extract_raw(sig, frame.get(), dlc) == 0);
    FUZZ_CHECK(!can::insert_raw(sig, raw_in, frame.get(), dlc));
    FUZZ_CHECK(!can::encode_signal(sig, value_in, frame.get(), dlc));
    FUZZ_CHECK(dlc == 0 || std::memcmp(frame.get(), copy.get(), dlc) == 0);
    return 0;
  }
  FUZZ_CHECK(sig.length_bits >= 1 && sig.length_bits <= 64);
  const int n = sig.length_bits;
  const std::uint64_t mask = n == 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << n) - 1;

  const std::uint64_t raw = can::extract_raw(sig, frame.get(), dlc);
  FUZZ_CHECK((raw & ~mask) == 0);
  FUZZ_CHECK(can::insert_raw(sig, raw, frame.get(), dlc));
  FUZZ_CHECK(std::memcmp(frame.get(), copy.get(), dlc) == 0);

  FUZZ_CHECK(can::insert_raw(sig, raw_in, frame.get(), dlc));
  FUZZ_CHECK(can::extract_raw(sig, frame.get(), dlc) == (raw_in & mask));
  FUZZ_CHECK(popcount_diff(frame.get(), copy.get(), dlc) == std::popcount((raw_in ^ raw) & mask));

  // Encoding: refused for non-finite input or scale, otherwise writes only the signal's bits.
  std::memcpy(frame.get(), copy.get(), dlc);
  const bool encoded = can::encode_signal(sig, value_in, frame.get(), dlc);
  if (!std::isfinite(value_in) || !std::isfinite(sig.scale) || sig.scale == 0.0) {
    FUZZ_CHECK(!encoded);
  }
  if (!encoded) {
    FUZZ_CHECK(std::memcmp(frame.get(), copy.get(), dlc) == 0);
  } else {
    const std::uint64_t written = can::extract_raw(sig, frame.get(), dlc);
    FUZZ_CHECK(popcount_diff(frame.get(), copy.get(), dlc) ==
               std::popcount((written ^ raw) & mask));
  }
  return 0;
}

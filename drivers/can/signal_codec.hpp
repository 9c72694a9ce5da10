#pragma once
// Pure DBC signal codec: no I/O, no allocation, safe on any input (fuzzable).

#include <cstddef>
#include <cstdint>

#include "drivers/can/can_settings.hpp"

namespace scp::drivers::can {

inline constexpr std::size_t kMaxPayload = 64;  // CAN FD

// True when every bit of the signal lies inside a payload of `dlc` bytes.
bool signal_fits(const CanSignal& sig, std::size_t dlc) noexcept;

// The raw (unscaled) bits of the signal, zero-extended; 0 when it does not fit.
std::uint64_t extract_raw(const CanSignal& sig, const std::uint8_t* data, std::size_t dlc) noexcept;
// Writes the low length_bits of `raw` into the signal's bits, leaving the others untouched.
bool insert_raw(const CanSignal& sig, std::uint64_t raw, std::uint8_t* data,
                std::size_t dlc) noexcept;

// raw · scale + offset, the raw value sign-extended when is_signed. NaN when the signal does not
// fit the payload. Out-of-range values (an all-ones "not available" pattern) are returned as they
// are: judging them is the safety layer's job.
double decode_signal(const CanSignal& sig, const std::uint8_t* data, std::size_t dlc) noexcept;

// Writes round((value − offset) / scale), saturated to the raw range of the signal. Returns false
// (payload untouched) for a non-finite value or a signal that does not fit.
bool encode_signal(const CanSignal& sig, double value, std::uint8_t* data,
                   std::size_t dlc) noexcept;

// True when the two signals share at least one bit (same frame assumed by the caller).
bool signals_overlap(const CanSignal& a, const CanSignal& b) noexcept;

}  // namespace scp::drivers::can

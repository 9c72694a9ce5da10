#pragma once
// Maximal-length Fibonacci LFSR, orders 2..31: the PRBS behind the excitation.

#include <cstdint>

namespace scp::excitation {

class Lfsr {
 public:
  static constexpr int kMinOrder = 2;
  static constexpr int kMaxOrder = 31;

  // `order` must be in [kMinOrder, kMaxOrder] (checked by the caller). Any seed gives a valid
  // nonzero start state.
  Lfsr(int order, std::uint32_t seed) noexcept;

  // The current output bit (0 or 1).
  int bit() const noexcept { return static_cast<int>(state_ & 1u); }
  void advance() noexcept;
  std::uint32_t state() const noexcept { return state_; }
  std::uint64_t period() const noexcept { return (std::uint64_t{1} << order_) - 1; }

 private:
  int order_;
  std::uint32_t taps_;  // feedback mask
  std::uint32_t state_;
};

}  // namespace scp::excitation

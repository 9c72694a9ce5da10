#include "excitation/lfsr.hpp"

#include <array>
#include <bit>

namespace scp::excitation {

namespace {

// Taps of primitive polynomials, one per order (Xilinx XAPP052, Table 3), as 1-based stage
// numbers; 0 ends a list. A primitive feedback polynomial is what makes the sequence
// maximal-length (period 2^n − 1, 2^(n−1) ones and 2^(n−1) − 1 zeros).
constexpr std::array<std::array<int, 4>, 32> kTaps = {{
    {0, 0, 0, 0},   {0, 0, 0, 0},    {2, 1, 0, 0},   {3, 2, 0, 0},   {4, 3, 0, 0},
    {5, 3, 0, 0},   {6, 5, 0, 0},    {7, 6, 0, 0},   {8, 6, 5, 4},   {9, 5, 0, 0},
    {10, 7, 0, 0},  {11, 9, 0, 0},   {12, 6, 4, 1},  {13, 4, 3, 1},  {14, 5, 3, 1},
    {15, 14, 0, 0}, {16, 15, 13, 4}, {17, 14, 0, 0}, {18, 11, 0, 0}, {19, 6, 2, 1},
    {20, 17, 0, 0}, {21, 19, 0, 0},  {22, 21, 0, 0}, {23, 18, 0, 0}, {24, 23, 22, 17},
    {25, 22, 0, 0}, {26, 6, 2, 1},   {27, 5, 2, 1},  {28, 25, 0, 0}, {29, 27, 0, 0},
    {30, 6, 4, 1},  {31, 28, 0, 0},
}};

}  // namespace

Lfsr::Lfsr(int order, std::uint32_t seed) noexcept : order_(order), taps_(0), state_(1) {
  if (order_ < kMinOrder || order_ > kMaxOrder) order_ = 7;
  for (int tap : kTaps[static_cast<std::size_t>(order_)]) {
    // Stage s (1-based, s = n is the output end of the shift) maps to bit n − s.
    if (tap > 0) taps_ |= std::uint32_t{1} << (order_ - tap);
  }
  // Map any seed onto 1..2^n − 1: the all-zero state is the LFSR's only fixed point.
  const std::uint64_t states = period();
  state_ = static_cast<std::uint32_t>(seed % states + 1);
}

void Lfsr::advance() noexcept {
  const std::uint32_t feedback = static_cast<std::uint32_t>(std::popcount(state_ & taps_)) & 1u;
  state_ = (state_ >> 1) | (feedback << (order_ - 1));
}

}  // namespace scp::excitation

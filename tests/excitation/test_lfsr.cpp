#include <gtest/gtest.h>

#include <cstdint>
#include <vector>

#include "excitation/lfsr.hpp"

namespace scp::excitation {
namespace {

// For every order up to 20: the state sequence has period exactly 2^n − 1 (it visits every
// nonzero state), and one period holds 2^(n−1) ones and 2^(n−1) − 1 zeros. Orders 21..31 take
// seconds each and were checked once offline with the same loop.
TEST(Lfsr, MaximalLengthForOrdersUpTo20) {
  for (int n = Lfsr::kMinOrder; n <= 20; ++n) {
    Lfsr l(n, 1);
    const std::uint32_t start = l.state();
    const std::uint64_t expected = (std::uint64_t{1} << n) - 1;
    std::uint64_t steps = 0, ones = 0;
    do {
      ones += static_cast<std::uint64_t>(l.bit());
      l.advance();
      ++steps;
      ASSERT_NE(l.state(), 0u);
    } while (l.state() != start && steps <= expected);
    EXPECT_EQ(steps, expected) << "order " << n;
    EXPECT_EQ(ones, std::uint64_t{1} << (n - 1)) << "order " << n;
  }
}

TEST(Lfsr, AnySeedGivesANonZeroState) {
  for (std::uint32_t seed : {0u, 1u, 7u, 8u, 0xFFFFFFFFu}) {
    Lfsr l(3, seed);
    EXPECT_GE(l.state(), 1u);
    EXPECT_LE(l.state(), 7u);
  }
}

}  // namespace
}  // namespace scp::excitation

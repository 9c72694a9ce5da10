#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "daemon/core/rt/alloc_counter.hpp"
#include "daemon/core/rt/loop_stats.hpp"

namespace scp::rt {
namespace {

using daemon::kHistogramBins;

TEST(LoopStats, BinEdgesAreZeroOneTwoFour) {
  EXPECT_EQ(lateness_bin_lower_us(0), 0.0);
  EXPECT_EQ(lateness_bin_lower_us(1), 1.0);
  EXPECT_EQ(lateness_bin_lower_us(2), 2.0);
  EXPECT_EQ(lateness_bin_lower_us(3), 4.0);
  EXPECT_EQ(lateness_bin_lower_us(11), 1024.0);
  EXPECT_EQ(lateness_bin(-3.0), 0U);
  EXPECT_EQ(lateness_bin(0.0), 0U);
  EXPECT_EQ(lateness_bin(0.999), 0U);
  EXPECT_EQ(lateness_bin(1.0), 1U);
  EXPECT_EQ(lateness_bin(1.999), 1U);
  EXPECT_EQ(lateness_bin(2.0), 2U);
  EXPECT_EQ(lateness_bin(3.5), 2U);
  EXPECT_EQ(lateness_bin(4.0), 3U);
  EXPECT_EQ(lateness_bin(1000.0), 10U);  // [512, 1024)
  EXPECT_EQ(lateness_bin(1e30), kHistogramBins - 1);
  EXPECT_EQ(lateness_bin(std::nan("")), 0U);
}

TEST(LoopStats, EmptyIsAllZero) {
  const LoopStatsAccumulator acc;
  const auto s = acc.snapshot();
  EXPECT_EQ(s.cycles, 0U);
  EXPECT_EQ(s.lateness_p99_us, 0.0);
  EXPECT_EQ(s.lateness_mean_us, 0.0);
}

TEST(LoopStats, MinMeanMaxCountsAndHistogram) {
  LoopStatsAccumulator acc;
  // Latenesses 3, 5, 40 µs and 0.2 µs: mean 12.05 µs.
  for (std::int64_t ns : {3'000, 5'000, 40'000, 200}) acc.record_lateness_ns(ns);
  acc.record_wake(
      WakeResult{.deadline_ns = 0, .cycle = 7, .lateness_ns = 1'500, .missed = 3, .overrun = true});
  acc.record_exec_ns(10'000);
  acc.record_exec(CycleEnd{.exec_ns = 30'000, .overran = false});
  const auto s = acc.snapshot();
  EXPECT_EQ(s.cycles, 5U);
  EXPECT_EQ(s.overruns, 1U);
  EXPECT_EQ(s.missed_periods, 3U);
  EXPECT_DOUBLE_EQ(s.lateness_min_us, 0.2);
  EXPECT_DOUBLE_EQ(s.lateness_max_us, 40.0);
  EXPECT_DOUBLE_EQ(s.lateness_mean_us, (3.0 + 5.0 + 40.0 + 0.2 + 1.5) / 5.0);
  EXPECT_DOUBLE_EQ(s.exec_mean_us, 20.0);
  EXPECT_DOUBLE_EQ(s.exec_max_us, 30.0);
  EXPECT_EQ(s.lateness_histogram[0], 1U);  // 0.2
  EXPECT_EQ(s.lateness_histogram[1], 1U);  // 1.5
  EXPECT_EQ(s.lateness_histogram[2], 1U);  // 3
  EXPECT_EQ(s.lateness_histogram[3], 1U);  // 5
  EXPECT_EQ(s.lateness_histogram[6], 1U);  // 40 in [32, 64)
  acc.reset();
  EXPECT_EQ(acc.snapshot().cycles, 0U);
}

TEST(LoopStats, P99InterpolatesWithinTheBin) {
  LoopStatsAccumulator acc;
  // 100 values evenly spread over [64, 128) µs, all in bin 7. The 99th-percentile rank 99 lies
  // 99/100 of the way through the bin: 64 + 64 · 0.99 = 127.36 µs.
  for (int i = 0; i < 100; ++i) acc.record_lateness_ns(64'000 + i * 640);
  EXPECT_NEAR(acc.snapshot().lateness_p99_us, 127.36, 1e-9);
}

TEST(LoopStats, P99FromARareTail) {
  LoopStatsAccumulator acc;
  // 980 wake-ups at 0.5 µs and 20 at 300 µs: the 99th percentile is in the tail's bin [256, 512),
  // halfway through its 20 samples (rank 990 = 980 + 10) → 256 + 256 · 10/20 = 384, clamped to
  // the observed maximum 300.
  for (int i = 0; i < 980; ++i) acc.record_lateness_ns(500);
  for (int i = 0; i < 20; ++i) acc.record_lateness_ns(300'000);
  EXPECT_DOUBLE_EQ(acc.snapshot().lateness_p99_us, 300.0);
}

TEST(LoopStats, P99WithinABinWidthOfTheExactPercentile) {
  std::mt19937_64 rng(42);
  std::lognormal_distribution<double> dist(std::log(20.0), 1.0);  // µs
  LoopStatsAccumulator acc;
  std::vector<double> values;
  for (int i = 0; i < 20000; ++i) {
    const double us = dist(rng);
    const auto ns = static_cast<std::int64_t>(std::llround(us * 1000.0));
    values.push_back(static_cast<double>(ns) * 1e-3);
    acc.record_lateness_ns(ns);
  }
  std::sort(values.begin(), values.end());
  const double exact = values[static_cast<std::size_t>(0.99 * values.size()) - 1];
  const double p99 = acc.snapshot().lateness_p99_us;
  // Both lie in the same logarithmic bin, so they differ by less than a factor of two.
  EXPECT_GT(p99, exact / 2.0);
  EXPECT_LT(p99, exact * 2.0);
}

TEST(LoopStats, OpenLastBinUsesTheMaximum) {
  LoopStatsAccumulator acc;
  const std::int64_t huge_ns = std::int64_t{1} << 41;  // ≈ 2.2e9 µs, beyond 2^30 µs
  acc.record_lateness_ns(huge_ns);
  const auto s = acc.snapshot();
  EXPECT_EQ(s.lateness_histogram[kHistogramBins - 1], 1U);
  EXPECT_DOUBLE_EQ(s.lateness_p99_us, static_cast<double>(huge_ns) * 1e-3);
}

TEST(LoopStats, RecordingAndFillingDoNotAllocate) {
  LoopStatsAccumulator acc;
  daemon::LoopStatistics out;
  alloc::arm();
  const alloc::ScopedAllocationCount count;
  for (int i = 0; i < 1000; ++i) {
    acc.record_wake(WakeResult{
        .deadline_ns = 0, .cycle = 0, .lateness_ns = i * 37, .missed = 0, .overrun = false});
    acc.record_exec_ns(i);
    acc.fill(out);
  }
  EXPECT_EQ(count.count(), 0U);
  alloc::disarm();
  EXPECT_EQ(out.cycles, 1000U);
}

}  // namespace
}  // namespace scp::rt

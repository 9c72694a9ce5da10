#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <random>
#include <thread>
#include <vector>

#include "daemon/core/rt/alloc_counter.hpp"
#include "daemon/core/rt/latency_histogram.hpp"

namespace scp::rt {
namespace {

using H = LatencyHistogram;

TEST(LatencyHistogram, BucketBoundsTileTheRangeWithinOnePercent) {
  // Exact 1 ns buckets below 256 ns, then 128 per octave.
  EXPECT_EQ(H::bucket_of(0), 0U);
  EXPECT_EQ(H::bucket_of(255), 255U);
  EXPECT_EQ(H::bucket_of(256), 256U);
  EXPECT_EQ(H::bucket_of(257), 256U);  // [256, 258)
  EXPECT_EQ(H::bucket_of(258), 257U);
  EXPECT_EQ(H::lower_ns(256), 256U);
  EXPECT_EQ(H::upper_ns(256), 258U);
  EXPECT_EQ(H::lower_ns(384), 512U);  // the next octave starts 128 buckets later
  EXPECT_EQ(H::upper_ns(384), 516U);
  EXPECT_EQ(H::bucket_of(std::uint64_t{1} << 40), H::kBuckets - 1);  // beyond 2^36: the last
  // Consecutive buckets touch, every value lies in its bucket, widths ≤ 1/128 of the lower edge.
  for (std::size_t i = 0; i + 1 < H::kBuckets; ++i) {
    ASSERT_EQ(H::upper_ns(i), H::lower_ns(i + 1)) << i;
    ASSERT_EQ(H::bucket_of(H::lower_ns(i)), i) << i;
    ASSERT_EQ(H::bucket_of(H::upper_ns(i) - 1), i) << i;
    if (i >= 2 * H::kSub) {
      ASSERT_LE(static_cast<double>(H::upper_ns(i) - H::lower_ns(i)),
                static_cast<double>(H::lower_ns(i)) / 128.0)
          << i;
    }
  }
  EXPECT_EQ(H::upper_ns(H::kBuckets - 1), std::uint64_t{1} << H::kMaxBits);
}

// Nearest-rank quantile of the sorted samples, the definition the histogram approximates.
double exact_quantile(const std::vector<std::int64_t>& sorted, double q) {
  const auto n = static_cast<double>(sorted.size());
  const auto rank = static_cast<std::size_t>(std::clamp(std::ceil(q * n), 1.0, n));
  return static_cast<double>(sorted[rank - 1]);
}

TEST(LatencyHistogram, PercentilesMatchASortedReferenceWithinHalfABucket) {
  // Loop-lateness-like data: a log-normal body around 30 µs and a heavy tail to tens of ms.
  std::mt19937_64 rng(12);
  std::lognormal_distribution<double> body(std::log(30e3), 0.5);
  std::uniform_real_distribution<double> tail(1e5, 3e7);
  std::bernoulli_distribution in_tail(0.003);
  auto hist = std::make_unique<H>();
  std::vector<std::int64_t> samples;
  for (int i = 0; i < 200000; ++i) {
    const auto v = static_cast<std::int64_t>(in_tail(rng) ? tail(rng) : body(rng));
    samples.push_back(v);
    hist->record(v);
  }
  std::sort(samples.begin(), samples.end());
  auto snap = std::make_unique<H::Snapshot>();
  hist->snapshot(*snap);
  EXPECT_EQ(snap->total, samples.size());
  EXPECT_EQ(snap->max_ns, static_cast<std::uint64_t>(samples.back()));
  for (double q : {0.0, 0.01, 0.5, 0.9, 0.99, 0.999, 0.9999, 1.0}) {
    const double exact = exact_quantile(samples, q);
    const double got = snap->quantile_ns(q);
    EXPECT_LE(std::abs(got - exact), exact / 256.0 + 0.5) << "q = " << q;
  }
  EXPECT_EQ(snap->quantile_ns(1.0), static_cast<double>(samples.back()));
}

TEST(LatencyHistogram, SmallValuesAreExactAndNegativeCountsAsZero) {
  auto hist = std::make_unique<H>();
  for (std::int64_t v : {-5, 0, 1, 2, 3, 100}) hist->record(v);
  auto snap = std::make_unique<H::Snapshot>();
  hist->snapshot(*snap);
  EXPECT_EQ(snap->counts[0], 2U);
  EXPECT_EQ(snap->quantile_ns(0.5), 1.0);  // rank 3 of {0, 0, 1, 2, 3, 100}
  EXPECT_EQ(snap->quantile_ns(1.0), 100.0);
  const H::Snapshot empty{};
  EXPECT_EQ(empty.quantile_ns(0.99), 0.0);
}

TEST(LatencyHistogram, RecordingAllocatesNothing) {
  auto hist = std::make_unique<H>();
  alloc::arm();
  const alloc::ScopedAllocationCount count;
  for (std::int64_t v = 0; v < 5'000'000'000; v = v * 3 + 7) hist->record(v);
  alloc::disarm();
  EXPECT_EQ(count.count(), 0U);
}

TEST(LatencyHistogram, AReaderSeesMonotoneCountsWhileTheWriterRecords) {
  auto hist = std::make_unique<H>();
  constexpr std::uint64_t kSamples = 2'000'000;
  std::thread writer([&] {
    for (std::uint64_t i = 0; i < kSamples; ++i)
      hist->record(static_cast<std::int64_t>(i % 100000));
  });
  auto snap = std::make_unique<H::Snapshot>();
  std::uint64_t last = 0;
  for (int i = 0; i < 50; ++i) {
    hist->snapshot(*snap);
    EXPECT_GE(snap->total, last);
    EXPECT_LE(snap->total, kSamples);
    last = snap->total;
  }
  writer.join();
  hist->snapshot(*snap);
  EXPECT_EQ(snap->total, kSamples);
  EXPECT_EQ(snap->max_ns, 99999U);
}

}  // namespace
}  // namespace scp::rt

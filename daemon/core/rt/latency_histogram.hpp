#pragma once
// Log-linear (HDR-style) histogram of non-negative nanosecond values with relative bucket width
// ≤ 1/128 (0.78 %), fixed memory (30 KiB), no allocation, and a lock-free export: one thread
// records (the loop), any number of threads read a snapshot at any time.
//
// Layout: values below 2·128 ns each have a bucket of their own (1 ns wide); above, every octave
// [2^k, 2^(k+1)) is split into 128 equal buckets of 2^(k−7) ns, so a bucket's width is at most
// 1/128 of its lower edge. Octaves run up to 2^36 ns (68.7 s); larger values share the last
// bucket, and the exact maximum is kept beside the buckets.
//
// Why relaxed atomics and not a seqlock: the loop would copy 30 KiB per cycle into a seqlock,
// while a reader may assemble the counts bucket by bucket. Each count only grows, a reader's copy
// is a histogram of the samples recorded up to roughly the moment of the copy (a count may miss
// the wake-up recorded during the copy), which is all a percentile needs. Single writer: a
// relaxed load + store per bucket, no read-modify-write, no lock prefix on the loop's path.

#include <array>
#include <atomic>
#include <bit>
#include <cstddef>
#include <cstdint>

namespace scp::rt {

class LatencyHistogram {
 public:
  static constexpr int kSubBits = 7;
  static constexpr std::uint64_t kSub = std::uint64_t{1} << kSubBits;  // buckets per octave
  static constexpr int kMaxBits = 36;                                  // 2^36 ns ≈ 68.7 s
  static constexpr std::size_t kBuckets = (kMaxBits - kSubBits + 1) * kSub;

  static constexpr std::size_t bucket_of(std::uint64_t ns) noexcept {
    if (ns < 2 * kSub) return static_cast<std::size_t>(ns);
    const int top = std::bit_width(ns) - 1;  // 2^top ≤ ns < 2^(top+1), top ≥ kSubBits + 1
    const int shift = top - kSubBits;
    const std::size_t index = static_cast<std::size_t>(shift) * kSub + (ns >> shift);
    return index < kBuckets ? index : kBuckets - 1;
  }
  // [lower, upper) of bucket `index` in ns (the last bucket also holds everything above).
  static constexpr std::uint64_t lower_ns(std::size_t index) noexcept {
    if (index < 2 * kSub) return index;
    const std::uint64_t shift = index / kSub - 1;
    return (index - shift * kSub) << shift;
  }
  static constexpr std::uint64_t upper_ns(std::size_t index) noexcept {
    if (index < 2 * kSub) return index + 1;
    return lower_ns(index) + (std::uint64_t{1} << (index / kSub - 1));
  }

  // Writer side: the loop thread only. A negative lateness (a wake-up on the nanosecond, clock
  // granularity) counts as 0.
  void record(std::int64_t ns) noexcept {
    const std::uint64_t v = ns > 0 ? static_cast<std::uint64_t>(ns) : 0;
    std::atomic<std::uint64_t>& c = counts_[bucket_of(v)];
    c.store(c.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
    if (v > max_ns_.load(std::memory_order_relaxed)) max_ns_.store(v, std::memory_order_relaxed);
  }

  // A plain copy for the reader: percentiles over the copied counts are self-consistent.
  struct Snapshot {
    std::array<std::uint64_t, kBuckets> counts{};
    std::uint64_t total = 0;
    std::uint64_t max_ns = 0;
    // Nearest-rank q-quantile (the ⌈q·n⌉-th smallest value), reported as the middle of its bucket
    // clamped to the maximum: within half a bucket (≤ 0.4 %, or 0.5 ns) of the exact order
    // statistic. 0 when empty.
    double quantile_ns(double q) const noexcept;
  };
  // Reader side: any thread, never blocks the writer. Fills `out` (30 KiB: keep it off small
  // stacks).
  void snapshot(Snapshot& out) const noexcept;

 private:
  std::array<std::atomic<std::uint64_t>, kBuckets> counts_{};
  std::atomic<std::uint64_t> max_ns_{0};
};

}  // namespace scp::rt

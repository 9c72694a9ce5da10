#pragma once
// Accumulates the loop's timing statistics (daemon/core/published_state.hpp: LoopStatistics) on the
// loop thread: fixed-size state, no allocation, O(kHistogramBins) per query, O(1) per sample.

#include <cstdint>

#include "daemon/core/published_state.hpp"
#include "daemon/core/rt/latency_histogram.hpp"
#include "daemon/core/rt/periodic_timer.hpp"

namespace scp::rt {

// Lower edge of histogram bin i in µs: 0, 1, 2, 4, 8, ... (bin i ≥ 1 starts at 2^(i−1) µs).
double lateness_bin_lower_us(std::size_t bin) noexcept;
// Bin a lateness (µs) falls in; negative and non-finite values go to bin 0 / the last bin.
std::size_t lateness_bin(double lateness_us) noexcept;

class LoopStatsAccumulator {
 public:
  // One wake-up: lateness, skipped periods and whether the previous cycle overran.
  void record_wake(const WakeResult& wake) noexcept;
  // One cycle's execution time (from PeriodicTimer::mark_cycle_end()).
  void record_exec(const CycleEnd& end) noexcept;
  // Lower-level entry points (for tests and for loops without PeriodicTimer).
  void record_lateness_ns(std::int64_t lateness_ns) noexcept;
  void record_exec_ns(std::int64_t exec_ns) noexcept;
  void add_overrun() noexcept { ++stats_.overruns; }
  void add_missed(std::uint64_t periods) noexcept { stats_.missed_periods += periods; }

  void reset() noexcept;

  // Also records every lateness into `fine` (may be null), the 1 %-resolution histogram that
  // STATUS reads lock-free from the server thread. It is not owned and survives reset().
  void attach(LatencyHistogram* fine) noexcept { fine_ = fine; }

  // Copies the statistics into `out`, computing the mean, the median and the 99th percentile: each
  // is read from the histogram, interpolated linearly within the bin that holds its rank
  // (the open last bin uses the observed maximum as its upper edge), then clamped to [min, max].
  // Its error is therefore at most the width of that bin — a factor of two, which is what a
  // logarithmic histogram can promise without storing samples.
  void fill(daemon::LoopStatistics& out) const noexcept;
  daemon::LoopStatistics snapshot() const noexcept {
    daemon::LoopStatistics s;
    fill(s);
    return s;
  }

 private:
  double percentile(double q) const noexcept;

  daemon::LoopStatistics stats_{};  // counters, min/max, histogram; means and p99 filled on demand
  double lateness_sum_us_ = 0.0;
  double exec_sum_us_ = 0.0;
  std::uint64_t exec_count_ = 0;
  LatencyHistogram* fine_ = nullptr;
};

}  // namespace scp::rt

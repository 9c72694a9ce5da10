#include "daemon/core/rt/loop_stats.hpp"

#include <algorithm>
#include <cmath>

namespace scp::rt {

using daemon::kHistogramBins;

double lateness_bin_lower_us(std::size_t bin) noexcept {
  if (bin == 0) return 0.0;
  return std::ldexp(1.0, static_cast<int>(bin) - 1);
}

std::size_t lateness_bin(double lateness_us) noexcept {
  if (std::isnan(lateness_us) || lateness_us < 1.0) return 0;
  if (!std::isfinite(lateness_us)) return kHistogramBins - 1;
  // lateness in [2^(i−1), 2^i) → bin i, i.e. i = floor(log2(lateness)) + 1.
  int exponent = 0;
  std::frexp(lateness_us, &exponent);  // lateness = f · 2^exponent, f in [0.5, 1)
  const auto bin = static_cast<std::size_t>(exponent);
  return std::min(bin, kHistogramBins - 1);
}

void LoopStatsAccumulator::record_wake(const WakeResult& wake) noexcept {
  record_lateness_ns(wake.lateness_ns);
  if (wake.overrun) add_overrun();
  add_missed(wake.missed);
}

void LoopStatsAccumulator::record_exec(const CycleEnd& end) noexcept {
  record_exec_ns(end.exec_ns);
}

void LoopStatsAccumulator::record_lateness_ns(std::int64_t lateness_ns) noexcept {
  const double us = static_cast<double>(lateness_ns) * 1e-3;
  if (stats_.cycles == 0) {
    stats_.lateness_min_us = us;
    stats_.lateness_max_us = us;
  } else {
    stats_.lateness_min_us = std::min(stats_.lateness_min_us, us);
    stats_.lateness_max_us = std::max(stats_.lateness_max_us, us);
  }
  ++stats_.cycles;
  lateness_sum_us_ += us;
  ++stats_.lateness_histogram[lateness_bin(us)];
  if (fine_ != nullptr) fine_->record(lateness_ns);
}

void LoopStatsAccumulator::record_exec_ns(std::int64_t exec_ns) noexcept {
  const double us = static_cast<double>(exec_ns) * 1e-3;
  stats_.exec_max_us = exec_count_ == 0 ? us : std::max(stats_.exec_max_us, us);
  ++exec_count_;
  exec_sum_us_ += us;
}

void LoopStatsAccumulator::reset() noexcept {
  LatencyHistogram* const fine = fine_;
  *this = LoopStatsAccumulator{};
  fine_ = fine;
}

void LoopStatsAccumulator::fill(daemon::LoopStatistics& out) const noexcept {
  out = stats_;
  out.lateness_mean_us =
      stats_.cycles ? lateness_sum_us_ / static_cast<double>(stats_.cycles) : 0.0;
  out.exec_mean_us = exec_count_ ? exec_sum_us_ / static_cast<double>(exec_count_) : 0.0;
  out.lateness_p50_us = percentile(0.50);
  out.lateness_p99_us = percentile(0.99);
}

double LoopStatsAccumulator::percentile(double q) const noexcept {
  if (stats_.cycles == 0) return 0.0;
  // Rank of the q-th quantile among the samples, as a continuous position in [0, n].
  const double n = static_cast<double>(stats_.cycles);
  const double rank = q * n;
  double below = 0.0;
  for (std::size_t i = 0; i < kHistogramBins; ++i) {
    const double count = static_cast<double>(stats_.lateness_histogram[i]);
    if (count == 0.0) continue;
    if (below + count >= rank) {
      const double lo = lateness_bin_lower_us(i);
      const double hi = i + 1 < kHistogramBins ? lateness_bin_lower_us(i + 1)
                                               : std::max(lo, stats_.lateness_max_us);
      const double p = lo + (hi - lo) * (rank - below) / count;
      return std::clamp(p, stats_.lateness_min_us, stats_.lateness_max_us);
    }
    below += count;
  }
  return stats_.lateness_max_us;
}

}  // namespace scp::rt

#include "daemon/core/rt/latency_histogram.hpp"

#include <algorithm>
#include <cmath>

namespace scp::rt {

void LatencyHistogram::snapshot(Snapshot& out) const noexcept {
  // The maximum last: every sample counted in the copy was recorded before it, so the maximum
  // read afterwards bounds them all.
  out.total = 0;
  for (std::size_t i = 0; i < kBuckets; ++i) {
    out.counts[i] = counts_[i].load(std::memory_order_relaxed);
    out.total += out.counts[i];
  }
  out.max_ns = max_ns_.load(std::memory_order_relaxed);
}

double LatencyHistogram::Snapshot::quantile_ns(double q) const noexcept {
  if (total == 0) return 0.0;
  // Nearest rank: the smallest value with at least ⌈q·n⌉ samples at or below it (rank ≥ 1).
  const double n = static_cast<double>(total);
  const auto rank =
      static_cast<std::uint64_t>(std::clamp(std::ceil(std::clamp(q, 0.0, 1.0) * n), 1.0, n));
  std::uint64_t below = 0;
  for (std::size_t i = 0; i < kBuckets; ++i) {
    below += counts[i];
    if (below >= rank) {
      const double mid =
          0.5 * (static_cast<double>(lower_ns(i)) + static_cast<double>(upper_ns(i) - 1));
      return std::min(mid, static_cast<double>(max_ns));
    }
  }
  return static_cast<double>(max_ns);
}

}  // namespace scp::rt

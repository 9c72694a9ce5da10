#pragma once
// A χ²_p process of moving windows: p coordinates, each the standardized sum of the last m white
// chunks, tested every chunk (β = 1/m, spacing 1 in scan_threshold.hpp's terms). An alarm is
// counted at an upcrossing of b, then none for m steps: the monitor re-arms only with a new
// reference. Without that dead time the count includes the re-crossings within one excursion,
// which the crossing-rate formula does not count. For test_scan_threshold.cpp and
// bench/bench_health_calibration.cpp.

#include <cstdint>
#include <deque>
#include <random>
#include <vector>

namespace scp::health::test {

inline double moving_window_alarm_rate(int dof, int m, double b, long steps, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n;
  std::vector<std::deque<double>> chunks(dof);
  std::vector<double> sums(dof, 0.0);
  long alarms = 0, dead_until = 0;
  bool above = false;
  for (long t = 0; t < steps + m; ++t) {
    double w = 0.0;
    for (int c = 0; c < dof; ++c) {
      const double x = n(rng);
      chunks[c].push_back(x);
      sums[c] += x;
      if (static_cast<int>(chunks[c].size()) > m) {
        sums[c] -= chunks[c].front();
        chunks[c].pop_front();
      }
      w += sums[c] * sums[c] / m;
    }
    if (t < m) continue;
    if (w > b && !above && t >= dead_until) {
      ++alarms;
      dead_until = t + m;
    }
    above = w > b;
  }
  return static_cast<double>(alarms) / static_cast<double>(steps);
}

}  // namespace scp::health::test

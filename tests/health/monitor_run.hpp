#pragma once
// Drives a HealthMonitor with synthetic windows (every chunk_s) and score blocks (every block_s)
// of a plant whose θ follows a given function of time, the blocks computed against the monitor's
// own reference as the daemon's simulator would. For the monitor tests and the benchmark.

#include <vector>

#include "health/monitor.hpp"
#include "tests/health/synthetic_windows.hpp"

namespace scp::health::test {

struct RunOptions {
  double duration_s = 3600.0;
  double window_s = 300.0;
  double chunk_s = 10.0;
  bool blocks = true;  // feed the fast detector
  Matrix6 window_covariance = window_covariance_300s();
  std::uint64_t seed = 1;
  double acknowledge_at_s =
      -1.0;                     // the user acknowledges at the first window after it (< 0: never)
  double misfit_from_s = -1.0;  // windows that end after it are misfits of the mechanical block
};

struct RunResult {
  std::vector<HealthEvent> events;
  HealthReport report;
  int changes() const {
    int n = 0;
    for (const auto& e : events) n += e.kind == EventKind::changed ? 1 : 0;
    return n;
  }
  int drifts() const {
    int n = 0;
    for (const auto& e : events) n += e.kind == EventKind::drift ? 1 : 0;
    return n;
  }
};

inline RunResult run_monitor(const HealthSettings& settings, const ThetaOfTime& theta,
                             const RunOptions& o) {
  const WindowEstimate baseline =
      baseline_window(theta(-0.5 * o.window_s), o.window_covariance, o.window_s, o.seed + 1000);
  HealthMonitor monitor(settings, baseline);
  WindowStream windows(theta, o.window_covariance, o.window_s, o.chunk_s, o.seed);
  ScoreStream scores(settings.block_s * (o.window_covariance * o.window_s).inverse(),
                     o.seed + 2000);
  RunResult result;
  double t_block = 0.0;
  bool acknowledged = false;
  // Windows end at window_s, window_s + chunk_s, ...; blocks fill the time between them.
  for (WindowEstimate w = windows.next(); w.t_end <= o.duration_s; w = windows.next()) {
    for (; o.blocks && t_block + settings.block_s <= w.t_end + 1e-9; t_block += settings.block_s) {
      const double mid = t_block + 0.5 * settings.block_s;
      const Reference ref = monitor.reference_at(mid);
      if (!ref.valid) continue;
      monitor.add_block(scores.block(t_block, t_block + settings.block_s, theta(mid), ref.theta));
    }
    w.misfit[0] = o.misfit_from_s >= 0.0 && w.t_end > o.misfit_from_s;
    monitor.add_window(w);
    if (o.acknowledge_at_s >= 0.0 && w.t_end >= o.acknowledge_at_s && !acknowledged) {
      monitor.acknowledge(w.t_end);
      acknowledged = true;
    }
    for (auto& e : monitor.take_events()) result.events.push_back(e);
  }
  result.report = monitor.report();
  return result;
}

}  // namespace scp::health::test

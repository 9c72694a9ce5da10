#pragma once
// The health monitor as the refinement's observer (refine::FitObserver): feeds the runner, and on
// every poll carries out the commands posted to the link, logs each event (one journal line per
// transition) and publishes the view. The service's worker thread polls it after each drain of
// the loop's ring; a batch run every cycle, keeping every event for its summary.

#include <vector>

#include "daemon/analysis/health/health_link.hpp"
#include "daemon/analysis/health/health_runner.hpp"

namespace scp::daemon::health {

class HealthAgent final : public refine::FitObserver {
 public:
  // `link` must outlive the agent. `keep_events`: keep every event for events() (a batch run).
  HealthAgent(const scp::health::HealthSettings& settings, HealthLink& link, bool keep_events);

  void poll() override;
  void on_sample(const scp::refine::WindowSample& sample) noexcept override {
    runner_.on_sample(sample);
  }
  void on_fit(const scp::refine::FitResult& fit, std::span<const scp::refine::WindowSample> window,
              std::int64_t wall_ns) override;

  const std::vector<scp::health::HealthEvent>& events() const noexcept { return events_; }
  HealthRunner& runner() noexcept { return runner_; }
  const HealthRunner& runner() const noexcept { return runner_; }

 private:
  HealthRunner runner_;
  HealthLink& link_;
  bool keep_events_;
  std::vector<scp::health::HealthEvent> events_;
};

}  // namespace scp::daemon::health

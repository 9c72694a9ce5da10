#include "daemon/analysis/health/health_agent.hpp"

namespace scp::daemon::health {

HealthAgent::HealthAgent(const scp::health::HealthSettings& settings, HealthLink& link,
                         bool keep_events)
    : runner_(settings), link_(link), keep_events_(keep_events) {
  link_.view().store(runner_.view());
}

void HealthAgent::poll() {
  for (const scp::health::HealthEvent& event : apply_commands(runner_, link_)) {
    log_event(event);
    if (keep_events_) events_.push_back(event);
  }
  link_.view().store(runner_.view());
}

void HealthAgent::on_fit(const scp::refine::FitResult& fit,
                         std::span<const scp::refine::WindowSample> window, std::int64_t wall_ns) {
  runner_.on_fit(fit, window, wall_ns);
  poll();
}

}  // namespace scp::daemon::health

#include "daemon/analysis/health/health_link.hpp"

#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdio>

namespace scp::daemon::health {

namespace {

using scp::health::EventKind;
using scp::health::kParameterNames;

std::string percent(double fraction, const char* format = "%+.1f %%") {
  char text[32];
  std::snprintf(text, sizeof(text), format, 100.0 * fraction);
  return text;
}

std::string candidate_list(const scp::health::ParameterMask& candidates) {
  std::string set;
  for (std::size_t i = 0; i < candidates.size(); ++i)
    if (candidates[i]) set += (set.empty() ? "" : ", ") + std::string(kParameterNames[i]);
  return set;
}

std::string describe_change(const scp::health::ChangePoint& c) {
  char head[128];
  std::snprintf(head, sizeof(head), "(onset %.1f s, %s detector)", c.onset,
                scp::health::detector_name(c.detector));
  std::string text = head;
  if (c.parameter < 0) {
    // Not yet named: the parameters the data do not yet tell apart (an event `named` follows).
    const std::string set = candidate_list(c.candidates);
    return set.empty() ? text : text + ": one of " + set;
  }
  const scp::health::ParameterShift& p = c.parameters[static_cast<std::size_t>(c.parameter)];
  const double reference = p.relative != 0.0 ? p.delta / p.relative : 0.0;
  const double relative_sigma = reference != 0.0 ? p.sigma / std::abs(reference) : 0.0;
  return text + ": " + kParameterNames[static_cast<std::size_t>(c.parameter)] + " " +
         percent(p.relative) + " (σ " + percent(relative_sigma, "%.2g %%") + ")";
}

// The drifting parameters with their slopes; a drift of repeated changes whose windows do not
// yet give a significant slope says since when and which parameters it may be.
std::string describe_drift(const scp::health::HealthEvent& event) {
  std::string text;
  for (std::size_t i = 0; i < event.trend.size(); ++i) {
    if (!event.trend[i].drifting) continue;
    text += (text.empty() ? "" : ", ") + std::string(kParameterNames[i]) + " " +
            percent(event.trend[i].relative_per_hour) + "/h";
  }
  const std::string set = candidate_list(event.change.candidates);
  if (set.empty()) return text.empty() ? text : ": " + text;
  // A drift that continues a change (monitor_chain.cpp) says since when, and what it may be
  // when its rate names no parameter.
  char head[64];
  std::snprintf(head, sizeof(head), " (changing since %.1f s): ", event.change.onset);
  return head + (text.empty() ? "one of " + set : text);
}

}  // namespace

std::vector<scp::health::HealthEvent> apply_commands(HealthRunner& runner, HealthLink& link) {
  for (HealthCommand& command : link.take()) {
    if (command.kind == HealthCommand::Kind::baseline) {
      runner.set_baseline(command.baseline, command.source);
    } else {
      runner.acknowledge(command.t);
    }
  }
  return runner.take_events();
}

std::string describe(const scp::health::HealthEvent& event) {
  char head[96];
  std::snprintf(head, sizeof(head), "%s at %.1f s", scp::health::event_name(event.kind), event.t);
  switch (event.kind) {
    case EventKind::changed:
    case EventKind::named:
      return head + std::string(" ") + describe_change(event.change);
    case EventKind::drift:
      return head + describe_drift(event);
    case EventKind::acknowledged:
      break;
  }
  return head;
}

void log_event(const scp::health::HealthEvent& event) {
  if (event.kind == EventKind::acknowledged) {
    spdlog::info("health: {}; state {}", describe(event), scp::health::state_name(event.state));
  } else {
    spdlog::warn("health: actuator {}", describe(event));
  }
}

}  // namespace scp::daemon::health

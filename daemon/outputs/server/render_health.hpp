#pragma once
// The `health` object of STATUS, ESTIMATE and HEALTH (docs/protocol.md, docs/health.md). Pure.

#include <nlohmann/json.hpp>

#include "daemon/analysis/health/health_view.hpp"

namespace scp::daemon::server {

// state: blind (no baseline), ok, drift or changed; since; the latest change point with its
// parameters named, size and σ; drift slopes; the fast detector's CUSUM ratios; the condition
// indicators; the latest window's deviation from the baseline. `full` adds every parameter's
// figures where the short form (STATUS, ESTIMATE) names only what moved.
nlohmann::json health_json(const health::HealthView& view, bool full = false);

}  // namespace scp::daemon::server

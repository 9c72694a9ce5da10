#pragma once
// The health monitor's settings: the daemon's `health.*` keys (docs/health.md). Plain data with
// the defaults of docs/health.md; validate() names the first bad key and its allowed range.

#include <string>

namespace scp::health {

struct HealthSettings {
  // The designed mean running time between false alarms of all detectors together (changed and
  // drift): a third each to the fast detector, the sure detector and the drift test.
  double false_alarm_days = 30.0;
  // A trend is a drift when its slope exceeds this fraction of |θ_i| per hour (significantly).
  double drift_per_hour = 0.05;
  // No parameter is named as changed by less than this fraction of |θ_i|, however significant:
  // a real bench's model misfit moves θ̂ by more than the fit's σ (issue 28).
  double min_relative_change = 0.02;
  // The step, as a fraction of |θ_i|, the fast detector's CUSUMs are tuned for (k = δ/2).
  double design_change = 0.10;
  // The fast detector's block: samples are summed over this long before the CUSUM sees them.
  double block_s = 1.0;
  // Trends use the windows of the last trend_span_s (since the last change at most).
  double trend_span_s = 3600.0;
  // The reference extrapolates a slope once its windows' midpoints span this long (a level
  // alone before).
  double trend_min_span_s = 120.0;
  // The actuator's heat capacity Cth in J/°C when known (R and λ are then published); 0 unknown.
  double heat_capacity_j_per_c = 0.0;
};

// "" when valid, else "health.KEY: why (allowed range)".
std::string validate(const HealthSettings& settings);

}  // namespace scp::health

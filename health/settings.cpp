#include "health/settings.hpp"

#include <cmath>

namespace scp::health {

namespace {

std::string range_error(const char* key, double value, double lo, double hi) {
  if (std::isfinite(value) && value >= lo && value <= hi) return "";
  return std::string("health.") + key + ": " + std::to_string(value) + " is outside [" +
         std::to_string(lo) + ", " + std::to_string(hi) + "]";
}

}  // namespace

std::string validate(const HealthSettings& s) {
  const struct {
    const char* key;
    double value, lo, hi;
  } checks[] = {
      {"false_alarm_days", s.false_alarm_days, 0.01, 1e5},
      {"drift_per_hour", s.drift_per_hour, 1e-6, 10.0},
      {"min_relative_change", s.min_relative_change, 0.0, 1.0},
      {"design_change", s.design_change, 1e-6, 10.0},
      {"block_s", s.block_s, 1e-3, 600.0},
      {"trend_span_s", s.trend_span_s, 60.0, 1e6},
      {"reference_span_s", s.reference_span_s, 60.0, 1e6},
      {"trend_min_span_s", s.trend_min_span_s, 0.0, 1e6},
      {"heat_capacity_j_per_c", s.heat_capacity_j_per_c, 0.0, 1e9},
  };
  for (const auto& c : checks) {
    std::string error = range_error(c.key, c.value, c.lo, c.hi);
    if (!error.empty()) return error;
  }
  if (s.reference_span_s > s.trend_span_s)
    return "health.reference_span_s: must not exceed health.trend_span_s (the windows kept)";
  if (s.trend_min_span_s > s.trend_span_s)
    return "health.trend_min_span_s: must not exceed health.trend_span_s";
  return "";
}

}  // namespace scp::health

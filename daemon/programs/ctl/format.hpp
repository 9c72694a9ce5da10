#pragma once
// Human-readable views of STATUS and ESTIMATE objects for scp-estimatorctl (--json prints them
// raw).

#include <nlohmann/json.hpp>
#include <string>

namespace scp::daemon::ctl {

// The daemon omits members it has no value for and sends null array elements: these print "-".
std::string number(const nlohmann::json& value, const char* format = "%.6g");
std::string member(const nlohmann::json& object, const char* key, const char* format = "%.6g");

std::string format_status(const nlohmann::json& status);
// A table: parameter, θ̂, σ, and θ / rel. error when present; physical parameters when present.
std::string format_estimate(const nlohmann::json& estimate);
// One line per ESTIMATE for `watch`.
std::string format_estimate_line(const nlohmann::json& estimate);
// The `health` object (HEALTH, STATUS): state, the latest change point, drifts, the latest
// window's deviation from the baseline.
std::string format_health(const nlohmann::json& health);
// A BASELINE reply: file, actuator, verdict, θ with σ.
std::string format_baseline(const nlohmann::json& baseline);

}  // namespace scp::daemon::ctl

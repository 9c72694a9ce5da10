#pragma once
// The Prometheus text exposition (format 0.0.4, what node_exporter's textfile collector and
// `promtool check metrics` read) of what STATUS and ESTIMATE already say (docs/protocol.md). It
// works from the two JSON replies, so that `scp-estimatorctl metrics` (a client of the socket)
// and the daemon's textfile writer (which renders the same replies) cannot disagree. Pure: no
// I/O, no clock.

#include <nlohmann/json.hpp>
#include <string>

namespace scp::daemon::metrics {

// `actuator` labels every sample (actuator.name; several daemons feed one node_exporter).
// Members missing from the replies (a non-finite number, a refinement not yet run) give no
// sample. Every metric has HELP and TYPE; counters end in _total; units are SI (seconds, volts).
std::string exposition(const nlohmann::json& status, const nlohmann::json& estimate,
                       const std::string& actuator);

// Escapes a label value: backslash, double quote and newline.
std::string label_value(const std::string& text);

}  // namespace scp::daemon::metrics

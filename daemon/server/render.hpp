#pragma once
// JSON rendering of every reply class (docs/protocol.md). Each function returns one complete line
// including the trailing '\n'. Pure functions: no I/O, no clock.

#include <string>
#include <string_view>

#include "daemon/published_state.hpp"
#include "daemon/server/settings.hpp"

namespace scp::daemon::server {

inline constexpr int kProtoMajor = 1;
inline constexpr int kProtoMinor = 0;

std::string render_version(std::string_view release);
std::string render_error(std::string_view message);
std::string render_ack(std::string_view request, bool ok, std::string_view message);
std::string render_watch(bool enable, double rate_hz);
std::string render_status(const PublishedState& state, const ServerInfo& info);
std::string render_estimate(const EstimateView& estimate);

// Lower edge (µs) of lateness histogram bin i: 0, 1, 2, 4, ..., 2^30 (published_state.hpp).
double histogram_lower_edge_us(std::size_t bin) noexcept;

// The RunState names used on the wire.
const char* state_name(RunState state) noexcept;

}  // namespace scp::daemon::server

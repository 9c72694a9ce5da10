#pragma once
// JSON rendering of every reply class (docs/protocol.md). Each function returns one complete line
// including the trailing '\n'. Pure functions: no I/O, no clock.

#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

#include "daemon/analysis/health/health_view.hpp"
#include "daemon/analysis/refine/refined_view.hpp"
#include "daemon/core/published_state.hpp"
#include "daemon/core/rt/latency_histogram.hpp"
#include "daemon/outputs/server/audit.hpp"
#include "daemon/outputs/server/settings.hpp"

namespace scp::daemon::server {

inline constexpr int kProtoMajor = 1;
// 1.1: refined, best, paper_biased; STATUS refine. 1.2: STATUS loop.lateness_us.p99_9 and
// loop.lateness_histogram_ns (1 % resolution); utc/unix_ns in ESTIMATE and STATUS; STATUS
// actuator, fault_count, recoveries, faults_cleared, last_fault, last_command, recording.
// 1.6: best none and best_reason, paper_validation, refined.validation, voltage_interval,
// nuisance and extensions (issue 28); `health` in STATUS and ESTIMATE; requests health,
// health-ack, baseline-show, baseline-save, baseline-clear (issue 30; docs/protocol.md).
// 1.9: refined.voltage_interval `undetermined` and refined.voltage_interval_test (issue 28).
// 1.11: refined.voltage_switches (a smooth voltage's switches and their phase, issue 28).
// 1.13: refined.voltage_switches.placed and phase_sigma (switches placed one by one, issue 28).
// 1.14: refined.warm_fallback structure_found (a warm refit whose validation finds structure).
// 1.15: a declared voltage interval weighed against the data: voltage_interval_test declared and
// contradicted, STATUS.refine.voltage_interval `contradicted` (issue 28).
// 1.16: refined.voltage_interval_test joint and thermal_statistic: where T̄ alone left the
// interval undetermined, both intervals' full fits weighed over x and T̄ together (issue 28).
// 1.17: refined.voltage_interval_test joint_lag_held: the two fits weighed with the sensor's lag
// held at 0 where both lags are a one-period shift in disguise (then `joint` also where the
// interval stays undetermined; issue 28).
inline constexpr int kProtoMinor = 17;

std::string render_version(std::string_view release);
std::string render_error(std::string_view message);
std::string render_ack(std::string_view request, bool ok, std::string_view message);
std::string render_watch(bool enable, double rate_hz);
// `refined` is null when the refinement is disabled (refine.enabled: false). With `lateness` (the
// loop's fine histogram) the lateness percentiles come from it and its non-empty buckets are
// listed; without it, from the coarse histogram in `state`. `last_command` is null until a
// mutating request arrived.
std::string render_status(const PublishedState& state, const ServerInfo& info,
                          const refine::RefinedView* refined = nullptr,
                          const rt::LatencyHistogram::Snapshot* lateness = nullptr,
                          const CommandRecord* last_command = nullptr,
                          const health::HealthView* health = nullptr);
// `now_t` is the loop time (PublishedState::uptime_s): the age of the refined fit decides `best`.
// `health` (null when the refinement is disabled) adds the short `health` object.
std::string render_estimate(const EstimateView& estimate,
                            const refine::RefinedView* refined = nullptr, double now_t = 0.0,
                            const health::HealthView* health = nullptr);
// The ESTIMATE object itself, which the batch summary extends (daemon/batch/).
nlohmann::json estimate_json(const EstimateView& estimate, const refine::RefinedView* refined,
                             double now_t, const health::HealthView* health = nullptr);

// Members with no value are omitted (the protocol's rule): `key` only when `value` is finite (a
// non-finite number has no JSON form).
void put_finite(nlohmann::json& object, const char* key, double value);

// "2026-11-23T08:30:00.123Z"
std::string utc_time(std::int64_t unix_ns);
// "utc" (ISO 8601, ms) and "unix_ns" (CLOCK_REALTIME, ns): omitted while unix_ns is 0.
void put_wall_clock(nlohmann::json& out, std::int64_t unix_ns);

// Lower edge (µs) of lateness histogram bin i: 0, 1, 2, 4, ..., 2^30 (published_state.hpp).
double histogram_lower_edge_us(std::size_t bin) noexcept;

}  // namespace scp::daemon::server

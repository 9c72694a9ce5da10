#include "daemon/server/render.hpp"

#include <cmath>
#include <cstring>
#include <nlohmann/json.hpp>

namespace scp::daemon::server {
namespace {

using nlohmann::json;

// Text from the loop or from a client may hold invalid UTF-8; replacing it keeps dump() from
// throwing and the reply a valid line.
std::string line(const json& object) {
  return object.dump(-1, ' ', false, json::error_handler_t::replace) + '\n';
}

std::string_view fixed_text(const std::array<char, kReasonChars>& text) noexcept {
  return {text.data(), strnlen(text.data(), text.size())};
}

// Members with no value are omitted (protocol rule); a non-finite number has no JSON form.
void put_finite(json& object, const char* key, double value) {
  if (std::isfinite(value)) object[key] = value;
}

// Inside fixed-length arrays the index carries meaning, so a non-finite element becomes null.
template <std::size_t N>
json number_array(const std::array<double, N>& values) {
  json out = json::array();
  for (double v : values) out.push_back(std::isfinite(v) ? json(v) : json(nullptr));
  return out;
}

}  // namespace

const char* state_name(RunState state) noexcept {
  switch (state) {
    case RunState::starting:
      return "starting";
    case RunState::running:
      return "running";
    case RunState::fault:
      return "fault";
    case RunState::stopping:
      return "stopping";
  }
  return "unknown";
}

double histogram_lower_edge_us(std::size_t bin) noexcept {
  return bin == 0 ? 0.0 : std::ldexp(1.0, static_cast<int>(bin) - 1);
}

std::string render_version(std::string_view release) {
  return line({{"class", "VERSION"},
               {"release", std::string(release)},
               {"proto_major", kProtoMajor},
               {"proto_minor", kProtoMinor}});
}

std::string render_error(std::string_view message) {
  return line({{"class", "ERROR"}, {"message", std::string(message)}});
}

std::string render_ack(std::string_view request, bool ok, std::string_view message) {
  json out = {{"class", "ACK"}, {"request", std::string(request)}, {"ok", ok}};
  if (!message.empty()) out["message"] = std::string(message);
  return line(out);
}

std::string render_watch(bool enable, double rate_hz) {
  json out = {{"class", "WATCH"}, {"enable", enable}};
  if (enable) out["rate_hz"] = rate_hz;
  return line(out);
}

std::string render_status(const PublishedState& state, const ServerInfo& info) {
  json out = {{"class", "STATUS"}, {"release", info.release}, {"driver", info.driver}};
  if (!info.config_file.empty()) out["config_file"] = info.config_file;
  out["state"] = state_name(state.state);
  const std::string_view reason = fixed_text(state.fault_reason);
  if (!reason.empty()) out["fault_reason"] = std::string(reason);
  put_finite(out, "uptime_s", state.uptime_s);
  put_finite(out, "period_s", state.period_s);
  out["excitation"] = state.excitation_enabled;
  put_finite(out, "voltage", state.voltage_command);

  json sample = json::object();
  put_finite(sample, "t", state.last_sample.t);
  put_finite(sample, "x", state.last_sample.x);
  put_finite(sample, "xdot", state.last_sample.xdot);
  put_finite(sample, "temperature", state.last_sample.temperature);
  put_finite(sample, "voltage", state.last_sample.voltage);
  out["sample"] = sample;

  const LoopStatistics& loop = state.loop;
  json lateness = json::object();
  put_finite(lateness, "min", loop.lateness_min_us);
  put_finite(lateness, "mean", loop.lateness_mean_us);
  put_finite(lateness, "p50", loop.lateness_p50_us);
  put_finite(lateness, "p99", loop.lateness_p99_us);
  put_finite(lateness, "max", loop.lateness_max_us);
  json exec = json::object();
  put_finite(exec, "mean", loop.exec_mean_us);
  put_finite(exec, "max", loop.exec_max_us);
  json edges = json::array();
  json counts = json::array();
  for (std::size_t i = 0; i < kHistogramBins; ++i) {
    edges.push_back(histogram_lower_edge_us(i));
    counts.push_back(loop.lateness_histogram[i]);
  }
  out["loop"] = {{"cycles", loop.cycles},
                 {"overruns", loop.overruns},
                 {"missed_periods", loop.missed_periods},
                 {"lateness_us", lateness},
                 {"exec_us", exec},
                 {"histogram", {{"edges_us", edges}, {"counts", counts}}}};
  if (loop.allocations_counted) out["loop"]["allocations"] = loop.allocations;

  const drivers::DriverStats& driver = state.driver;
  out["driver_stats"] = {{"reads", driver.reads},     {"read_errors", driver.read_errors},
                         {"writes", driver.writes},   {"write_errors", driver.write_errors},
                         {"dropped", driver.dropped}, {"reconnects", driver.reconnects},
                         {"link_up", driver.link_up}};
  return line(out);
}

std::string render_estimate(const EstimateView& estimate) {
  json out = {{"class", "ESTIMATE"}};
  put_finite(out, "t", estimate.t);
  out["theta_hat"] = number_array(estimate.theta_hat);
  out["sigma"] = number_array(estimate.sigma);
  out["eps"] = number_array(estimate.eps);
  out["af"] = number_array(estimate.af);
  out["af_hat"] = number_array(estimate.af_hat);
  json excitation = json::object();
  put_finite(excitation, "mechanical", estimate.excitation[0]);
  put_finite(excitation, "thermal", estimate.excitation[1]);
  out["excitation"] = excitation;
  json p_max_eig = json::object();
  put_finite(p_max_eig, "mechanical", estimate.p_max_eig[0]);
  put_finite(p_max_eig, "thermal", estimate.p_max_eig[1]);
  out["p_max_eig"] = p_max_eig;
  out["converged"] = {{"mechanical", estimate.converged[0]}, {"thermal", estimate.converged[1]}};
  out["updates"] = estimate.updates;
  out["skipped"] = estimate.skipped;
  if (estimate.has_truth) {
    out["theta_true"] = number_array(estimate.theta_true);
    std::array<double, 6> rel{};
    for (std::size_t i = 0; i < rel.size(); ++i) {
      // A zero true value has no relative error; NaN renders as null.
      const double truth = estimate.theta_true[i];
      rel[i] = truth != 0.0 ? std::abs(estimate.theta_hat[i] - truth) / std::abs(truth)
                            : std::numeric_limits<double>::quiet_NaN();
    }
    out["rel_error"] = number_array(rel);
  }
  if (estimate.has_physical) {
    static constexpr std::array<const char*, 6> kNames{"b",      "k",      "alpha1",
                                                       "alpha2", "lambda", "Cth"};
    json physical = json::object();
    for (std::size_t i = 0; i < kNames.size(); ++i)
      put_finite(physical, kNames[i], estimate.physical[i]);
    out["physical"] = physical;
  }
  return line(out);
}

}  // namespace scp::daemon::server

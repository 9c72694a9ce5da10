#include "daemon/outputs/server/render_health.hpp"

#include <cmath>

#include "daemon/outputs/server/render.hpp"

namespace scp::daemon::server {

namespace {

using nlohmann::json;
using scp::health::kBlockNames;
using scp::health::kParameterNames;
using scp::health::kParams;

json shift_json(int i, const scp::health::ParameterShift& p) {
  json out = {{"parameter", kParameterNames[static_cast<std::size_t>(i)]}};
  put_finite(out, "delta", p.delta);
  put_finite(out, "sigma", p.sigma);
  put_finite(out, "z", p.z);
  put_finite(out, "relative", p.relative);
  return out;
}

json change_json(const scp::health::ChangePoint& c, bool full) {
  json out = {{"detector", scp::health::detector_name(c.detector)}};
  put_finite(out, "onset", c.onset);
  put_finite(out, "detected_at", c.detected_at);
  if (c.parameter >= 0) out["parameter"] = kParameterNames[static_cast<std::size_t>(c.parameter)];
  json parameters = json::array();
  for (int i = 0; i < kParams; ++i) {
    const auto& p = c.parameters[static_cast<std::size_t>(i)];
    // The short form names the parameter found first and whatever moved beyond 2σ with it.
    if (!p.tested || (!full && i != c.parameter && !(std::abs(p.z) >= 2.0))) continue;
    parameters.push_back(shift_json(i, p));
  }
  out["parameters"] = std::move(parameters);
  return out;
}

json drift_json(const scp::health::DriftReport& d, bool full) {
  json out = {{"valid", d.valid}, {"windows", d.windows}, {"data_span_s", d.data_span_s}};
  json parameters = json::array();
  for (int i = 0; i < kParams; ++i) {
    const auto& p = d.parameters[static_cast<std::size_t>(i)];
    if (!p.tested || (!full && !p.drifting)) continue;
    json item = {{"parameter", kParameterNames[static_cast<std::size_t>(i)]},
                 {"drifting", p.drifting}};
    put_finite(item, "per_hour", p.per_hour);
    put_finite(item, "sigma_per_hour", p.sigma_per_hour);
    put_finite(item, "relative_per_hour", p.relative_per_hour);
    parameters.push_back(std::move(item));
  }
  out["parameters"] = std::move(parameters);
  return out;
}

json wald_json(const scp::health::WaldResult& w) {
  json blocks = json::object();
  for (int b = 0; b < scp::health::kBlocks; ++b) {
    const auto& block = w.blocks[static_cast<std::size_t>(b)];
    json item = {{"dof", block.dof}, {"significant", block.significant}};
    put_finite(item, "chi2", block.statistic);
    put_finite(item, "threshold", block.threshold);
    blocks[kBlockNames[static_cast<std::size_t>(b)]] = std::move(item);
  }
  json parameters = json::array();
  for (int i = 0; i < kParams; ++i) {
    const auto& p = w.parameters[static_cast<std::size_t>(i)];
    if (p.tested) parameters.push_back(shift_json(i, p));
  }
  return {{"blocks", std::move(blocks)}, {"parameters", std::move(parameters)}};
}

json indicators_json(const scp::health::Indicators& indicators) {
  json out = json::object();
  for (int i = 0; i < scp::health::kIndicators; ++i) {
    const auto& v = indicators[static_cast<std::size_t>(i)];
    if (!v.known) continue;
    json item = json::object();
    put_finite(item, "value", v.value);
    put_finite(item, "sigma", v.sigma);
    out[scp::health::kIndicatorNames[static_cast<std::size_t>(i)]] = std::move(item);
  }
  return out;
}

json fast_json(const scp::health::FastReport& f) {
  json ratio = json::object();
  for (int i = 0; i < kParams; ++i)
    put_finite(ratio, kParameterNames[static_cast<std::size_t>(i)],
               f.ratio[static_cast<std::size_t>(i)]);
  return {{"active", f.active}, {"blocks", f.blocks}, {"cusum_ratio", std::move(ratio)}};
}

void put_full(json& out, const health::HealthView& v) {
  const scp::health::HealthReport& r = v.report;
  out["drift"] = drift_json(r.drift, true);
  out["fast"] = fast_json(r.fast);
  if (r.has_window) {
    out["baseline_deviation"] = wald_json(r.baseline_deviation);
    out["indicators"] = indicators_json(r.indicators);
  }
  out["baseline_indicators"] = indicators_json(r.baseline_indicators);
  out["windows"] = r.windows;
  out["windows_rejected"] = r.windows_rejected;
  out["dismissed"] = r.dismissed;
  out["drift_alarms"] = r.drift_alarms;
  out["acknowledged"] = r.acknowledged;
  out["residual_samples"] = v.residual_samples;
  out["residual_variance_ratio"] = {{"x", v.residual_variance_ratio[0]},
                                    {"T", v.residual_variance_ratio[1]}};
  out["baseline_estimate"] = {{"file", std::string(v.baseline_file.data())},
                              {"theta", v.baseline_theta},
                              {"sigma", v.baseline_sigma}};
  put_wall_clock(out["baseline_estimate"], v.baseline_saved_unix_ns);
  if (v.last_window_unix_ns != 0) {
    out["last_window"] = json::object();
    put_wall_clock(out["last_window"], v.last_window_unix_ns);
  }
}

}  // namespace

json health_json(const health::HealthView& v, bool full) {
  if (!v.baseline_present) {
    return {{"state", "blind"},
            {"baseline", false},
            {"reason",
             "no baseline: save one with 'scp-estimatorctl baseline save' once the "
             "refined estimate has converged"}};
  }
  const scp::health::HealthReport& r = v.report;
  json out = {{"state", scp::health::state_name(r.state)},
              {"since", r.since},
              {"baseline", true},
              {"changes", r.changes},
              {"drifts", r.drifts}};
  if (r.has_change) out["change"] = change_json(r.change, full);
  if (r.drift.valid) out["drift"] = drift_json(r.drift, false);
  if (full) put_full(out, v);
  return out;
}

}  // namespace scp::daemon::server

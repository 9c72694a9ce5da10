#include "daemon/outputs/server/render.hpp"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <limits>
#include <nlohmann/json.hpp>

#include "daemon/analysis/refine/best.hpp"
#include "daemon/outputs/server/render_health.hpp"

namespace scp::daemon::server {

void put_finite(nlohmann::json& object, const char* key, double value) {
  if (std::isfinite(value)) object[key] = value;
}

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

// Inside fixed-length arrays the index carries meaning, so a non-finite element becomes null.
template <std::size_t N>
json number_array(const std::array<double, N>& values) {
  json out = json::array();
  for (double v : values) out.push_back(std::isfinite(v) ? json(v) : json(nullptr));
  return out;
}

// |θ̂ᵢ − θᵢ| / |θᵢ|; a zero true value has no relative error (NaN renders as null).
json relative_errors(const std::array<double, 6>& hat, const std::array<double, 6>& truth) {
  std::array<double, 6> rel{};
  for (std::size_t i = 0; i < rel.size(); ++i) {
    rel[i] = truth[i] != 0.0 ? std::abs(hat[i] - truth[i]) / std::abs(truth[i])
                             : std::numeric_limits<double>::quiet_NaN();
  }
  return number_array(rel);
}

json per_block(const std::array<bool, 2>& flags) {
  return {{"mechanical", flags[0]}, {"thermal", flags[1]}};
}

json channels(const std::array<double, 2>& values) {
  json out = json::object();
  put_finite(out, "x", values[0]);
  put_finite(out, "T", values[1]);
  return out;
}

}  // namespace

std::string utc_time(std::int64_t unix_ns) {
  const std::time_t seconds = static_cast<std::time_t>(unix_ns / 1'000'000'000);
  const auto millis = static_cast<int>((unix_ns % 1'000'000'000) / 1'000'000);
  std::tm tm{};
  gmtime_r(&seconds, &tm);
  char text[40];
  const std::size_t n = std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%S", &tm);
  std::snprintf(text + n, sizeof text - n, ".%03dZ", millis);
  return text;
}

void put_wall_clock(json& out, std::int64_t unix_ns) {
  if (unix_ns <= 0) return;  // not yet published by a cycle
  out["utc"] = utc_time(unix_ns);
  out["unix_ns"] = unix_ns;
}

namespace {

// STATUS "fault_count", "recoveries", "faults_cleared" and, after the first fault, "last_fault".
void put_fault_history(json& out, const FaultHistory& faults) {
  out["fault_count"] = faults.count;
  out["recoveries"] = faults.recoveries;
  out["faults_cleared"] = faults.cleared;
  if (faults.count == 0) return;
  json last = {{"reason", std::string(fixed_text(faults.last_reason))}};
  put_finite(last, "t", faults.last_t);
  put_wall_clock(last, faults.last_unix_ns);
  out["last_fault"] = last;
}

// One block's verdict (refine/validation.hpp): its decisive test and the failing tests, each with
// the effect it estimates (the missing term's size, NaN = none: omitted).
json block_validation(const scp::refine::ValidationReport& report, scp::refine::ValidationBlock b) {
  const scp::refine::BlockReport& block = report.block(b);
  json o = json::object();
  o["verdict"] = scp::refine::verdict_name(block.verdict);
  o["decisive"] = scp::refine::test_name(block.decisive);
  put_finite(o, "fit_percent", block.fit_percent);
  put_finite(o, "residual_rms", block.residual_rms);
  if (block.noise_ratio > 0.0) put_finite(o, "noise_ratio", block.noise_ratio);
  put_finite(o, "block_s", block.block_s);
  o["blocks"] = block.blocks;
  json failed = json::array();
  for (int i = 0; i < scp::refine::kValidationTests; ++i) {
    const auto test = static_cast<scp::refine::ValidationTest>(i);
    const scp::refine::TestOutcome& t = report.outcome(test);
    if (scp::refine::block_of(test) != b || !t.performed || !t.failed) continue;
    json f = {{"test", scp::refine::test_name(test)}};
    put_finite(f, "p_value", t.p_value);
    put_finite(f, "effect", t.effect);
    failed.push_back(f);
  }
  o["failed"] = failed;
  return o;
}

json validation_json(const scp::refine::ValidationReport& report) {
  return {{"mechanical", block_validation(report, scp::refine::ValidationBlock::kMechanical)},
          {"thermal", block_validation(report, scp::refine::ValidationBlock::kThermal)},
          {"samples", report.samples}};
}

// refined.nuisance: the terms the fit estimated or held at a value (a term it neither estimated
// nor was told about is left out); refined.extensions: those not off.
void put_bench_terms(json& o, const refine::RefinedView& r) {
  json nuisance = json::object();
  const std::pair<const char*, const scp::refine::NuisanceEstimate*> terms[] = {
      {"x_zero", &r.nuisance.x_zero},
      {"ambient_offset", &r.nuisance.ambient_offset},
      {"ambient_drift", &r.nuisance.ambient_drift},
      {"sensor_lag", &r.nuisance.sensor_lag}};
  for (const auto& [name, n] : terms) {
    if (!n->estimated && n->value == 0.0) continue;
    json t = {{"estimated", n->estimated}};
    put_finite(t, "value", n->value);
    put_finite(t, "sigma", n->sigma);
    nuisance[name] = t;
  }
  if (!nuisance.empty()) o["nuisance"] = nuisance;
  json extensions = json::object();
  const std::pair<const char*, const scp::refine::ExtensionEstimate*> exts[] = {
      {"resistance_tempco", &r.extensions.resistance_tempco},
      {"stiffness_softening", &r.extensions.stiffness_softening},
      {"cooling_tempco", &r.extensions.cooling_tempco}};
  for (const auto& [name, e] : exts) {
    if (e->mode == scp::refine::ExtensionMode::off) continue;
    json t = {{"mode", scp::refine::to_text(e->mode)}, {"kept", e->kept}};
    put_finite(t, "value", e->value);
    put_finite(t, "sigma", e->sigma);
    if (e->criterion != scp::refine::InformationCriterion::none) {
      t["criterion"] = scp::refine::to_text(e->criterion);
      put_finite(t, "criterion_difference", e->criterion_difference);
    }
    extensions[name] = t;
  }
  if (!extensions.empty()) o["extensions"] = extensions;
  if (r.heater.measured) {
    // The thermal input was the measured power V·I (refine/heater_power.hpp).
    json heater = {{"input", "measured_power"}};
    put_finite(heater, "r0_ohm", r.heater.r0_ohm);
    put_finite(heater, "r0_sigma_ohm", r.heater.r0_sigma_ohm);
    put_finite(heater, "rho", r.heater.rho);
    put_finite(heater, "rho_sigma", r.heater.rho_sigma);
    o["heater"] = heater;
  }
}

// "voltage_interval" (before, after, or undetermined where the data could not tell and θ depends
// on it), a smooth voltage's "voltage_switches" where it has any (with how many the fit placed
// each in its own interval, and their phases' RMS σ), and, when the fit estimated the
// interval or weighed a declared one, "voltage_interval_test": what it fitted with and the
// criterion's evidence.
void put_voltage_interval(json& o, const refine::RefinedView& r) {
  const bool undetermined = refine::interval_undetermined(r);
  o["voltage_interval"] = undetermined ? "undetermined" : scp::refine::to_text(r.voltage_interval);
  if (r.voltage_switches.count > 0) {
    json switches = {{"count", r.voltage_switches.count}, {"phase", r.voltage_switches.phase}};
    if (r.voltage_switches.placed > 0) {
      switches["placed"] = r.voltage_switches.placed;
      put_finite(switches, "phase_sigma", r.voltage_switches.rms_phase_sigma);
    }
    o["voltage_switches"] = switches;
  }
  const scp::refine::IntervalEvidence& e = r.voltage_interval_evidence;
  if (!e.estimated && !e.checked) return;
  json test = {{"fitted", scp::refine::to_text(r.voltage_interval)}, {"determined", e.determined}};
  if (e.checked) {
    test["declared"] = true;
    test["contradicted"] = e.contradicted;
  }
  put_finite(test, "statistic", e.statistic);
  put_finite(test, "threshold", e.threshold);
  if (e.joint) {
    test["joint"] = true;
    test["joint_lag_held"] = e.joint_lag_held;
    put_finite(test, "thermal_statistic", e.thermal_statistic);
  }
  if (e.compared) {
    test["equivalent"] = e.equivalent;
    put_finite(test, "theta_shift_sigma", e.theta_shift_sigma);
  }
  o["voltage_interval_test"] = test;
}

// The members the refinement adds to ESTIMATE: "paper_biased", "best", "best_reason" and, once a
// fit exists, "refined" and "paper_validation" (docs/protocol.md). `refined` may be null.
void put_refinement(json& out, const EstimateView& estimate, const refine::RefinedView* refined,
                    double now_t) {
  const bool fitted = refined != nullptr && refined->valid;
  out["paper_biased"] = per_block(fitted ? refined->paper_biased : std::array<bool, 2>{});
  const refine::BestChoice best = refine::best_estimate(refined, now_t);
  out["best"] = refine::best_name(best.best);
  if (!best.reason.empty()) out["best_reason"] = best.reason;
  if (!fitted) return;
  const refine::RefinedView& r = *refined;
  if (r.paper_validated) out["paper_validation"] = validation_json(r.paper_validation);
  json o = json::object();
  o["theta_hat"] = number_array(r.theta_hat);
  o["sigma"] = number_array(r.sigma);
  o["sigma_inflation"] = number_array(r.sigma_inflation);
  json window = json::object();
  put_finite(window, "t_begin", r.t_begin);
  put_finite(window, "t_end", r.t_end);
  window["samples"] = r.samples;
  o["window"] = window;
  json fitted_at = json::object();
  put_finite(fitted_at, "t", r.fitted_at_t);
  fitted_at["utc"] = utc_time(r.fitted_at_unix_ns);
  fitted_at["unix_ns"] = r.fitted_at_unix_ns;
  o["fitted_at"] = fitted_at;
  put_finite(o, "duration_s", r.duration_s);
  o["residual_rms"] = channels(r.residual_rms);
  o["noise_sigma"] = channels(r.noise_sigma);
  if (r.input_delay_estimated) {
    json timing = json::object();
    put_finite(timing, "input_delay_s", r.input_delay_s);
    put_finite(timing, "input_delay_sigma_s", r.input_delay_sigma_s);
    put_finite(timing, "input_delay_sigma_inflation", r.input_delay_sigma_inflation);
    put_finite(timing, "sample_jitter_s", r.sample_timing_sigma_s);
    timing["outliers"] = r.outliers;
    o["link_timing"] = timing;
  }
  o["converged"] = r.converged;
  o["iterations"] = r.iterations;
  o["evaluations"] = r.evaluations;
  o["warm"] = r.warm;
  if (!r.warm && r.warm_fallback != scp::refine::WarmFallback::not_requested)
    o["warm_fallback"] = scp::refine::to_text(r.warm_fallback);
  put_voltage_interval(o, r);
  if (r.validated) o["validation"] = validation_json(r.validation);
  put_bench_terms(o, r);
  const std::string_view message{r.message.data(), strnlen(r.message.data(), r.message.size())};
  if (!message.empty()) o["message"] = std::string(message);
  o["seed"] = refine::seed_name(r.seed);
  o["fits"] = r.fits;
  o["converged_fits"] = r.converged_fits;
  o["warm_fits"] = r.warm_fits;
  o["windows"] = r.windows;
  if (r.bias_tested) {
    json test = json::object();
    for (std::size_t b = 0; b < 2; ++b) {
      json block = json::object();
      put_finite(block, "statistic", r.bias_statistic[b]);
      put_finite(block, "threshold", r.bias_threshold[b]);
      test[b == 0 ? "mechanical" : "thermal"] = block;
    }
    o["bias_test"] = test;
  }
  if (estimate.has_truth) {
    o["theta_true"] = number_array(estimate.theta_true);
    o["rel_error"] = relative_errors(r.theta_hat, estimate.theta_true);
  }
  out["refined"] = o;
}

}  // namespace

namespace {

// The fine histogram's non-empty buckets as [lower_ns, upper_ns, count] (upper exclusive): a
// client subtracts two of them to get the percentiles of the window between (scripts/bench).
json fine_buckets(const rt::LatencyHistogram::Snapshot& h) {
  json buckets = json::array();
  for (std::size_t i = 0; i < h.counts.size(); ++i) {
    if (h.counts[i] == 0) continue;
    buckets.push_back(
        {rt::LatencyHistogram::lower_ns(i), rt::LatencyHistogram::upper_ns(i), h.counts[i]});
  }
  return {{"buckets", buckets}, {"count", h.total}, {"max", h.max_ns}};
}

}  // namespace

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

std::string render_status(const PublishedState& state, const ServerInfo& info,
                          const refine::RefinedView* refined,
                          const rt::LatencyHistogram::Snapshot* lateness_ns,
                          const CommandRecord* last_command, const health::HealthView* health) {
  json out = {{"class", "STATUS"}, {"release", info.release}, {"driver", info.driver}};
  if (!info.actuator.empty()) out["actuator"] = info.actuator;
  if (!info.config_file.empty()) out["config_file"] = info.config_file;
  out["state"] = to_string(state.state);
  const std::string_view reason = fixed_text(state.fault_reason);
  if (!reason.empty()) out["fault_reason"] = std::string(reason);
  if (state.state == RunState::starting && state.awaiting_device) {
    // The device has not delivered a reading since start: say why while waiting for it.
    const std::string_view waiting = fixed_text(state.waiting_reason);
    out["waiting_for_device"] = waiting.empty() ? "first reading" : std::string(waiting);
  }
  put_wall_clock(out, state.unix_ns);
  put_fault_history(out, state.faults);
  put_finite(out, "uptime_s", state.uptime_s);
  put_finite(out, "period_s", state.period_s);
  out["excitation"] = state.excitation_enabled;
  // The voltage the device acknowledged, not the loop's wish: when the 0 V of a fault could not
  // be delivered (link down) the device may still hold it, and "output" says so.
  put_finite(out, "voltage", state.driver.output_v);
  put_finite(out, "voltage_command", state.voltage_command);
  out["output"] = state.driver.output_confirmed ? "confirmed" : "unconfirmed";

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
  if (lateness_ns != nullptr && lateness_ns->total > 0) {
    put_finite(lateness, "p50", lateness_ns->quantile_ns(0.50) * 1e-3);
    put_finite(lateness, "p99", lateness_ns->quantile_ns(0.99) * 1e-3);
    put_finite(lateness, "p99_9", lateness_ns->quantile_ns(0.999) * 1e-3);
  } else {
    put_finite(lateness, "p50", loop.lateness_p50_us);
    put_finite(lateness, "p99", loop.lateness_p99_us);
  }
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
  if (lateness_ns != nullptr) out["loop"]["lateness_histogram_ns"] = fine_buckets(*lateness_ns);

  const drivers::DriverStats& driver = state.driver;
  out["driver_stats"] = {{"reads", driver.reads},
                         {"read_errors", driver.read_errors},
                         {"writes", driver.writes},
                         {"write_errors", driver.write_errors},
                         {"dropped", driver.dropped},
                         {"reconnects", driver.reconnects},
                         {"late_replies", driver.late_replies},
                         {"stretched_stamps", driver.stretched_stamps},
                         {"link_up", driver.link_up}};
  if (driver.last_error != nullptr && driver.last_error[0] != '\0')
    out["driver_stats"]["last_error"] = driver.last_error;
  if (refined != nullptr) {
    json r = {{"fits", refined->fits},
              {"converged_fits", refined->converged_fits},
              {"warm_fits", refined->warm_fits},
              {"windows", refined->windows},
              {"handoff_dropped", state.handoff_dropped}};
    if (refined->valid) {
      put_finite(r, "last_fit_duration_s", refined->duration_s);
      if (refine::interval_undetermined(*refined)) r["voltage_interval"] = "undetermined";
      if (refine::interval_contradicted(*refined)) r["voltage_interval"] = "contradicted";
    }
    out["refine"] = r;
  }
  if (last_command != nullptr) put_last_command(out, *last_command);
  if (state.recording) out["recording"] = {{"dropped_rows", state.record_dropped}};
  if (health != nullptr) out["health"] = health_json(*health, /*full=*/true);
  return line(out);
}

std::string render_estimate(const EstimateView& estimate, const refine::RefinedView* refined,
                            double now_t, const health::HealthView* health) {
  return line(estimate_json(estimate, refined, now_t, health));
}

json estimate_json(const EstimateView& estimate, const refine::RefinedView* refined, double now_t,
                   const health::HealthView* health) {
  json out = {{"class", "ESTIMATE"}};
  if (health != nullptr) out["health"] = health_json(*health, /*full=*/false);
  put_finite(out, "t", estimate.t);
  put_wall_clock(out, estimate.unix_ns);
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
    out["rel_error"] = relative_errors(estimate.theta_hat, estimate.theta_true);
  }
  if (estimate.has_physical) {
    static constexpr std::array<const char*, 6> kNames{"b",      "k",      "alpha1",
                                                       "alpha2", "lambda", "Cth"};
    json physical = json::object();
    for (std::size_t i = 0; i < kNames.size(); ++i)
      put_finite(physical, kNames[i], estimate.physical[i]);
    out["physical"] = physical;
  }
  put_refinement(out, estimate, refined, now_t);
  return out;
}

}  // namespace scp::daemon::server

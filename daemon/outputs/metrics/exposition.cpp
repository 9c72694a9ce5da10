#include "daemon/outputs/metrics/exposition.hpp"

#include <array>
#include <cmath>
#include <cstdio>
#include <string_view>

#include "daemon/core/published_state.hpp"
#include "health/types.hpp"
#include "refine/validation.hpp"

namespace scp::daemon::metrics {
namespace {

using nlohmann::json;

// θ's components (docs/numerics.md), as label values.
constexpr std::array<const char*, 6> kParameters{"b_over_m",      "alpha1_over_m",   "k_over_m",
                                                 "alpha2_over_m", "lambda_over_cth", "inv_r_cth"};
static_assert(kParameters.size() == scp::health::kParameterNames.size(),
              "a label value for each of the protocol's parameter names");

std::string number(double value) {
  if (std::isinf(value)) return value > 0 ? "+Inf" : "-Inf";
  char text[40];
  std::snprintf(text, sizeof text, "%.17g", value);
  return text;
}

class Writer {
 public:
  explicit Writer(const std::string& actuator)
      : base_label_("actuator=\"" + label_value(actuator) + "\"") {}

  // HELP and TYPE once per metric, before its first sample.
  void family(std::string_view name, std::string_view type, std::string_view help) {
    out_ += "# HELP ";
    out_ += name;
    out_ += ' ';
    out_ += help;
    out_ += "\n# TYPE ";
    out_ += name;
    out_ += ' ';
    out_ += type;
    out_ += '\n';
  }
  void sample(std::string_view name, double value, const std::string& labels = {}) {
    if (std::isnan(value)) return;
    out_ += name;
    out_ += '{';
    out_ += base_label_;
    if (!labels.empty()) {
      out_ += ',';
      out_ += labels;
    }
    out_ += "} ";
    out_ += number(value);
    out_ += '\n';
  }
  // A metric with one sample, when the member exists.
  void single(std::string_view name, std::string_view type, std::string_view help,
              const json& object, const char* key, double scale = 1.0) {
    const auto it = object.find(key);
    if (it == object.end() || !(it->is_number() || it->is_boolean())) return;
    family(name, type, help);
    sample(name, it->is_boolean() ? (it->get<bool>() ? 1.0 : 0.0) : it->get<double>() * scale);
  }
  std::string take() { return std::move(out_); }

 private:
  std::string base_label_;
  std::string out_;
};

double get(const json& object, const char* key, double otherwise = NAN) {
  const auto it = object.find(key);
  return it != object.end() && it->is_number() ? it->get<double>() : otherwise;
}

void identity_metrics(Writer& w, const json& status) {
  w.family("scp_estimator_info", "gauge", "the daemon's release and driver (value 1)");
  w.sample("scp_estimator_info", 1.0,
           "release=\"" + label_value(status.value("release", "")) + "\",driver=\"" +
               label_value(status.value("driver", "")) + "\"");
  w.family("scp_estimator_state", "gauge", "1 for the loop's current state, 0 for the others");
  const std::string state = status.value("state", "");
  for (const auto& [value, name] : kRunStateNames) {
    w.sample("scp_estimator_state", state == name ? 1.0 : 0.0,
             std::string("state=\"") + name + "\"");
  }
  w.single("scp_estimator_uptime_seconds", "gauge", "loop time since the loop started", status,
           "uptime_s");
  w.single("scp_estimator_snapshot_timestamp_seconds", "gauge",
           "wall-clock time (Unix epoch) of the snapshot these values come from", status, "unix_ns",
           1e-9);
}

void output_metrics(Writer& w, const json& status) {
  w.single("scp_estimator_excitation_enabled", "gauge", "1 when the excitation signal is on",
           status, "excitation");
  w.single("scp_estimator_output_volts", "gauge", "voltage the device last acknowledged", status,
           "voltage");
  w.single("scp_estimator_output_command_volts", "gauge",
           "voltage the loop commanded this cycle, after the safety clamp", status,
           "voltage_command");
  w.family("scp_estimator_output_confirmed", "gauge",
           "1 when the device acknowledged the latest command");
  w.sample("scp_estimator_output_confirmed", status.value("output", "") == "confirmed" ? 1 : 0);
  w.single("scp_estimator_faults_total", "counter", "entries into the fault state since start",
           status, "fault_count");
  w.single("scp_estimator_fault_recoveries_total", "counter",
           "driver faults that cleared by themselves", status, "recoveries");
  w.single("scp_estimator_faults_cleared_total", "counter", "faults cleared by clear-fault", status,
           "faults_cleared");
  if (status.contains("last_fault") && status["last_fault"].is_object())
    w.single("scp_estimator_last_fault_timestamp_seconds", "gauge",
             "wall-clock time (Unix epoch) of the latest fault", status["last_fault"], "unix_ns",
             1e-9);
}

// The loop's lateness histogram as a Prometheus histogram: bucket le = the upper edge of each
// bin, cumulative. The sum is mean × count (the loop keeps no exact sum).
void lateness_histogram(Writer& w, const json& histogram, const json& lateness) {
  const json edges = histogram.value("edges_us", json::array());
  const json counts = histogram.value("counts", json::array());
  if (!edges.is_array() || !counts.is_array() || edges.size() != counts.size() || edges.empty()) {
    return;
  }
  const std::string name = "scp_estimator_loop_lateness_seconds";
  w.family(name, "histogram", "wake-up lateness of the loop after its deadline");
  double cumulative = 0.0;
  for (std::size_t i = 0; i + 1 < edges.size(); ++i) {
    cumulative += counts[i].get<double>();
    w.sample(name + "_bucket", cumulative,
             "le=\"" + number(edges[i + 1].get<double>() * 1e-6) + "\"");
  }
  cumulative += counts.back().get<double>();
  w.sample(name + "_bucket", cumulative, "le=\"+Inf\"");
  w.sample(name + "_sum", get(lateness, "mean", 0.0) * 1e-6 * cumulative);
  w.sample(name + "_count", cumulative);
}

void loop_metrics(Writer& w, const json& status) {
  const json loop = status.value("loop", json::object());
  w.single("scp_estimator_loop_cycles_total", "counter", "loop cycles run", loop, "cycles");
  w.single("scp_estimator_loop_overruns_total", "counter",
           "cycles whose work ran past the next deadline", loop, "overruns");
  w.single("scp_estimator_loop_missed_periods_total", "counter",
           "periods skipped to resynchronise after overruns", loop, "missed_periods");
  const json lateness = loop.value("lateness_us", json::object());
  w.single("scp_estimator_loop_lateness_max_seconds", "gauge",
           "largest wake-up lateness since start", lateness, "max", 1e-6);
  w.single("scp_estimator_loop_lateness_p99_seconds", "gauge",
           "99th percentile of the wake-up lateness since start (from the histogram)", lateness,
           "p99", 1e-6);
  const json exec = loop.value("exec_us", json::object());
  w.single("scp_estimator_loop_exec_max_seconds", "gauge", "longest cycle execution time", exec,
           "max", 1e-6);
  w.single("scp_estimator_loop_exec_mean_seconds", "gauge", "mean cycle execution time", exec,
           "mean", 1e-6);
  lateness_histogram(w, loop.value("histogram", json::object()), lateness);
}

void driver_metrics(Writer& w, const json& status) {
  const json driver = status.value("driver_stats", json::object());
  static constexpr std::array<std::array<const char*, 3>, 8> kDriverCounters{{
      {"reads", "scp_estimator_driver_reads_total", "driver read transactions"},
      {"read_errors", "scp_estimator_driver_read_errors_total", "failed driver reads"},
      {"writes", "scp_estimator_driver_writes_total", "driver write transactions"},
      {"write_errors", "scp_estimator_driver_write_errors_total", "failed driver writes"},
      {"dropped", "scp_estimator_driver_dropped_total",
       "frames that arrived but could not be used"},
      {"reconnects", "scp_estimator_driver_reconnects_total", "reconnections of the link"},
      {"late_replies", "scp_estimator_driver_late_replies_total",
       "replies that came after their timeout and were discarded"},
      {"stretched_stamps", "scp_estimator_driver_stretched_stamps_total",
       "transactions too long for their midpoint to stamp the device's event"},
  }};
  for (const auto& [key, name, help] : kDriverCounters)
    w.single(name, "counter", help, driver, key);
  w.single("scp_estimator_driver_link_up", "gauge", "1 while the device answers", driver,
           "link_up");
}

void service_metrics(Writer& w, const json& status) {
  if (status.contains("recording") && status["recording"].is_object())
    w.single("scp_estimator_recording_dropped_rows_total", "counter",
             "recording rows the loop dropped because the recorder's ring was full",
             status["recording"], "dropped_rows");
  if (status.contains("refine") && status["refine"].is_object()) {
    const json& refine = status["refine"];
    w.single("scp_estimator_refine_fits_total", "counter", "output-error fits finished", refine,
             "fits");
    w.single("scp_estimator_refine_converged_fits_total", "counter",
             "output-error fits that converged", refine, "converged_fits");
    w.single("scp_estimator_refine_handoff_dropped_total", "counter",
             "samples the refinement's hand-off ring had no room for", refine, "handoff_dropped");
  }
}

void theta_samples(Writer& w, const char* name, const json& values, const char* estimator) {
  if (!values.is_array()) return;
  for (std::size_t i = 0; i < values.size() && i < kParameters.size(); ++i) {
    if (!values[i].is_number()) continue;
    w.sample(name, values[i].get<double>(),
             std::string("estimator=\"") + estimator + "\",parameter=\"" + kParameters[i] + "\"");
  }
}

// The model validation of each estimate (ESTIMATE refined.validation, paper_validation; issue 28):
// the verdict per block as a state set (1 for the current verdict), its fit % and noise ratio.
void validation_metrics(Writer& w, const json& estimate) {
  const json none;
  const std::pair<const char*, const json*> sources[] = {
      {"paper", estimate.contains("paper_validation") ? &estimate["paper_validation"] : &none},
      {"refined", estimate.contains("refined") && estimate["refined"].is_object() &&
                          estimate["refined"].contains("validation")
                      ? &estimate["refined"]["validation"]
                      : &none}};
  if (!sources[0].second->is_object() && !sources[1].second->is_object()) return;
  using scp::refine::Verdict;
  constexpr Verdict kVerdicts[] = {Verdict::kAdequate, Verdict::kNoiseColored, Verdict::kStructure,
                                   Verdict::kUntested};
  const auto each_block = [&](auto&& emit) {
    for (const auto& [who, v] : sources) {
      if (!v->is_object()) continue;
      for (const char* block : {"mechanical", "thermal"}) {
        if (!v->contains(block) || !(*v)[block].is_object()) continue;
        emit((*v)[block], std::string("estimator=\"") + who + "\",block=\"" + block + "\"");
      }
    }
  };
  w.family("scp_estimator_validation_verdict", "gauge",
           "model validation verdict of the block (docs/validation.md): 1 for the current one");
  each_block([&](const json& b, const std::string& labels) {
    const std::string verdict = b.value("verdict", std::string());
    for (const Verdict each : kVerdicts) {
      const char* name = scp::refine::verdict_name(each);
      w.sample("scp_estimator_validation_verdict", verdict == name ? 1 : 0,
               labels + ",verdict=\"" + name + "\"");
    }
  });
  w.family("scp_estimator_validation_fit_percent", "gauge",
           "NRMSE fit % of the simulated model per block (MATLAB compare)");
  each_block([&](const json& b, const std::string& labels) {
    if (b.contains("fit_percent") && b["fit_percent"].is_number())
      w.sample("scp_estimator_validation_fit_percent", b["fit_percent"].get<double>(), labels);
  });
  w.family("scp_estimator_validation_noise_ratio", "gauge",
           "residual RMS over the declared sensor noise (sensors.noise), per block");
  each_block([&](const json& b, const std::string& labels) {
    if (b.contains("noise_ratio") && b["noise_ratio"].is_number())
      w.sample("scp_estimator_validation_noise_ratio", b["noise_ratio"].get<double>(), labels);
  });
}

void estimate_metrics(Writer& w, const json& estimate) {
  const bool refined = estimate.contains("refined") && estimate["refined"].is_object();
  w.family("scp_estimator_theta", "gauge",
           "estimated parameter (docs/numerics.md): paper = the online law, refined = the "
           "output-error fit");
  theta_samples(w, "scp_estimator_theta", estimate.value("theta_hat", json()), "paper");
  if (refined)
    theta_samples(w, "scp_estimator_theta", estimate["refined"].value("theta_hat", json()),
                  "refined");
  w.family("scp_estimator_theta_sigma", "gauge", "standard deviation of the estimated parameter");
  theta_samples(w, "scp_estimator_theta_sigma", estimate.value("sigma", json()), "paper");
  if (refined)
    theta_samples(w, "scp_estimator_theta_sigma", estimate["refined"].value("sigma", json()),
                  "refined");
  if (estimate.contains("converged") && estimate["converged"].is_object()) {
    w.family("scp_estimator_converged", "gauge",
             "1 when every sigma_i/|theta_i| of the block is below estimator.converged_rel_sigma");
    for (const auto& [block, flag] : estimate["converged"].items())
      if (flag.is_boolean())
        w.sample("scp_estimator_converged", flag.get<bool>() ? 1 : 0,
                 "block=\"" + label_value(block) + "\"");
  }
  if (estimate.contains("best") && estimate["best"].is_string()) {
    w.family("scp_estimator_best_refined", "gauge",
             "1 when the refined estimate is the better one (ESTIMATE best), 0 for the paper's");
    w.sample("scp_estimator_best_refined", estimate["best"] == "refined" ? 1 : 0);
    w.family("scp_estimator_best", "gauge",
             "the estimate the daemon recommends (ESTIMATE best): 1 for it; none = neither "
             "passed its validation");
    for (const char* name : {"refined", "paper", "none"})
      w.sample("scp_estimator_best", estimate["best"] == name ? 1 : 0,
               std::string("estimate=\"") + name + "\"");
  }
  validation_metrics(w, estimate);
  w.single("scp_estimator_estimate_updates_total", "counter", "estimator updates", estimate,
           "updates");
  w.single("scp_estimator_estimate_skipped_total", "counter",
           "samples the estimator rejected (non-finite, out of range, time)", estimate, "skipped");
  w.single("scp_estimator_estimate_loop_time_seconds", "gauge",
           "loop time of the latest estimator update", estimate, "t");
}

// The protocol's parameter names (health/types.hpp) to this exposition's label values.
std::string parameter_label(const std::string& protocol_name) {
  const auto& protocol = scp::health::kParameterNames;
  for (std::size_t i = 0; i < protocol.size(); ++i)
    if (protocol_name == protocol[i]) return std::string("parameter=\"") + kParameters[i] + "\"";
  return "parameter=\"" + label_value(protocol_name) + "\"";
}

void health_state_metrics(Writer& w, const json& h) {
  w.family("scp_estimator_health_state", "gauge",
           "1 for the actuator's health state (ok, drift, changed; blind without a baseline)");
  const std::string state = h.value("state", "blind");
  for (const char* name : {"blind", "ok", "drift", "changed"}) {
    w.sample("scp_estimator_health_state", state == name ? 1.0 : 0.0,
             std::string("state=\"") + name + "\"");
  }
  w.family("scp_estimator_health_baseline_present", "gauge", "1 when a baseline is loaded");
  w.sample("scp_estimator_health_baseline_present", h.value("baseline", false) ? 1.0 : 0.0);
  w.single("scp_estimator_health_changes_total", "counter", "change points found", h, "changes");
  w.single("scp_estimator_health_drifts_total", "counter", "drifts raised", h, "drifts");
  w.single("scp_estimator_health_dismissed_total", "counter",
           "fast alarms whose change was below health.min_relative_change", h, "dismissed");
  if (h.contains("last_window"))
    w.single("scp_estimator_health_last_window_timestamp_seconds", "gauge",
             "wall-clock time (Unix epoch) of the last refined window the monitor was given",
             h["last_window"], "unix_ns", 1e-9);
}

void health_deviation_metrics(Writer& w, const json& deviation) {
  const auto found = deviation.find("blocks");
  if (found == deviation.end() || !found->is_object()) return;
  const json& blocks = *found;
  w.family("scp_estimator_health_baseline_chi2", "gauge",
           "the latest refined window's Wald statistic against the baseline, per block");
  for (const auto& [block, b] : blocks.items())
    w.sample("scp_estimator_health_baseline_chi2", get(b, "chi2"), "block=\"" + block + "\"");
  w.family("scp_estimator_health_baseline_chi2_threshold", "gauge",
           "its threshold at the designed false-alarm rate");
  for (const auto& [block, b] : blocks.items())
    w.sample("scp_estimator_health_baseline_chi2_threshold", get(b, "threshold"),
             "block=\"" + block + "\"");
  w.family("scp_estimator_health_baseline_relative", "gauge",
           "(θ̂ − θ_baseline)/|θ_baseline| of the latest refined window");
  for (const json& p : deviation.value("parameters", json::array()))
    w.sample("scp_estimator_health_baseline_relative", get(p, "relative"),
             parameter_label(p.value("parameter", "")));
  w.family("scp_estimator_health_baseline_z", "gauge",
           "(θ̂ − θ_baseline)/σ of the latest refined window, σ from both covariances");
  for (const json& p : deviation.value("parameters", json::array()))
    w.sample("scp_estimator_health_baseline_z", get(p, "z"),
             parameter_label(p.value("parameter", "")));
}

void health_detector_metrics(Writer& w, const json& h) {
  if (h.contains("drift")) {
    w.family("scp_estimator_health_slope_relative_per_hour", "gauge",
             "the drift test's slope, as a fraction of |θ| per hour");
    for (const json& p : h["drift"].value("parameters", json::array()))
      w.sample("scp_estimator_health_slope_relative_per_hour", get(p, "relative_per_hour"),
               parameter_label(p.value("parameter", "")));
  }
  if (h.contains("indicators")) {
    const json& indicators = h["indicators"];
    w.family("scp_estimator_health_indicator", "gauge",
             "condition indicators of the latest refined window (docs/health.md)");
    for (const auto& [name, v] : indicators.items())
      w.sample("scp_estimator_health_indicator", get(v, "value"), "indicator=\"" + name + "\"");
    w.family("scp_estimator_health_indicator_sigma", "gauge", "their standard deviations");
    for (const auto& [name, v] : indicators.items())
      w.sample("scp_estimator_health_indicator_sigma", get(v, "sigma"),
               "indicator=\"" + name + "\"");
  }
  if (h.contains("fast")) {
    w.family("scp_estimator_health_cusum_ratio", "gauge",
             "the fast detector's max(g+, g-)/h per parameter (1 alarms)");
    const json& fast = h["fast"];
    const auto ratios = fast.find("cusum_ratio");
    if (ratios == fast.end() || !ratios->is_object()) return;
    for (const auto& [name, value] : ratios->items())
      w.sample("scp_estimator_health_cusum_ratio", value.is_number() ? value.get<double>() : NAN,
               parameter_label(name));
  }
}

// STATUS `health` (full): absent when the refinement is off.
void health_metrics(Writer& w, const json& status) {
  const auto it = status.find("health");
  if (it == status.end() || !it->is_object()) return;
  health_state_metrics(w, *it);
  if (it->contains("baseline_deviation")) health_deviation_metrics(w, (*it)["baseline_deviation"]);
  health_detector_metrics(w, *it);
}

}  // namespace

std::string label_value(const std::string& text) {
  std::string out;
  for (const char c : text) {
    if (c == '\\') {
      out += "\\\\";
    } else if (c == '"') {
      out += "\\\"";
    } else if (c == '\n') {
      out += "\\n";
    } else {
      out += c;
    }
  }
  return out;
}

std::string exposition(const json& status, const json& estimate, const std::string& actuator) {
  Writer w(actuator);
  identity_metrics(w, status);
  output_metrics(w, status);
  loop_metrics(w, status);
  driver_metrics(w, status);
  service_metrics(w, status);
  estimate_metrics(w, estimate);
  health_metrics(w, status);
  return w.take();
}

}  // namespace scp::daemon::metrics

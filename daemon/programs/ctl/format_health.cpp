#include <algorithm>
#include <cmath>
#include <string>

#include "daemon/programs/ctl/format.hpp"

namespace scp::daemon::ctl {
namespace {

using nlohmann::json;

std::string shift_line(const json& p) {
  const double relative = p.value("relative", 0.0);
  const double delta = p.value("delta", 0.0);
  const double reference = relative != 0.0 ? delta / relative : 0.0;
  const auto sigma = p.find("sigma");
  const json sigma_percent = reference != 0.0 && sigma != p.end() && sigma->is_number()
                                 ? json(100.0 * sigma->get<double>() / std::abs(reference))
                                 : json();
  return "  " + p.value("parameter", std::string("?")) + "  " +
         number(json(100.0 * relative), "%+.1f %%") + "  (σ " + number(sigma_percent, "%.1f %%") +
         ", z " + member(p, "z", "%.1f") + ")\n";
}

std::string change_text(const json& change) {
  std::string out = "change found at " + member(change, "detected_at", "%.1f") + " s, onset " +
                    member(change, "onset", "%.1f") + " s, by the " +
                    change.value("detector", std::string("?")) + " detector:\n";
  for (const json& p : change.value("parameters", json::array())) out += shift_line(p);
  return out;
}

std::string drift_text(const json& drift) {
  std::string out;
  for (const json& p : drift.value("parameters", json::array())) {
    if (!p.value("drifting", false)) continue;
    out += "  " + p.value("parameter", std::string("?")) + "  " +
           number(json(100.0 * p.value("relative_per_hour", 0.0)), "%+.2f %%/h") + "\n";
  }
  return out.empty() ? out : "drifting:\n" + out;
}

std::string deviation_text(const json& deviation) {
  std::string out = "latest window against the baseline:\n";
  for (const auto& [name, block] : deviation.value("blocks", json::object()).items()) {
    out += "  " + name + "  χ² " + member(block, "chi2", "%.1f") + " (threshold " +
           member(block, "threshold", "%.1f") + ")\n";
  }
  for (const json& p : deviation.value("parameters", json::array())) out += shift_line(p);
  return out;
}

}  // namespace

std::string format_health(const json& health) {
  const std::string state = health.value("state", std::string("-"));
  if (state == "blind") return "state: blind (" + health.value("reason", std::string()) + ")\n";
  std::string out = "state: " + state + " since " + member(health, "since", "%.1f") +
                    " s (changes " + std::to_string(health.value("changes", 0)) + ", drifts " +
                    std::to_string(health.value("drifts", 0)) + ")\n";
  if (health.contains("change")) out += change_text(health["change"]);
  if (health.contains("drift")) out += drift_text(health["drift"]);
  if (health.contains("baseline_deviation")) out += deviation_text(health["baseline_deviation"]);
  return out;
}

std::string format_baseline(const json& baseline) {
  if (!baseline.value("present", false))
    return "no baseline (" + baseline.value("file", std::string()) + ")\n";
  std::string out = "baseline " + baseline.value("file", std::string()) + "\n  actuator " +
                    baseline.value("actuator", std::string("-")) + ", validation " +
                    baseline.value("verdict", std::string("-")) + ", window [" +
                    member(baseline, "t_begin", "%.1f") + ", " + member(baseline, "t_end", "%.1f") +
                    "] s\n";
  const json theta = baseline.value("theta", json::array());
  const json cov = baseline.value("covariance", json::array());
  for (std::size_t i = 0; i < theta.size() && i < 6; ++i) {
    const json variance = cov.size() == 36 ? cov[7 * i] : json();
    out += "  θ" + std::to_string(i + 1) + "  " + number(theta[i], "%.6g") + "  σ " +
           (variance.is_number()
                ? number(json(std::sqrt(std::max(0.0, variance.get<double>()))), "%.3g")
                : std::string("-")) +
           "\n";
  }
  return out;
}

}  // namespace scp::daemon::ctl

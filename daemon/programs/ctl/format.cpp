#include "daemon/programs/ctl/format.hpp"

#include <array>
#include <cstdio>

namespace scp::daemon::ctl {

std::string number(const nlohmann::json& value, const char* format) {
  if (!value.is_number()) return "-";
  char text[64];
  std::snprintf(text, sizeof(text), format, value.get<double>());
  return text;
}

std::string member(const nlohmann::json& object, const char* key, const char* format) {
  if (!object.is_object()) return "-";
  const auto it = object.find(key);
  return it == object.end() ? "-" : number(*it, format);
}

namespace {

using nlohmann::json;

constexpr std::array<const char*, 6> kThetaNames{"b/m",      "alpha1/m",   "k/m",
                                                 "alpha2/m", "lambda/Cth", "1/(R*Cth)"};

std::string element(const json& array, std::size_t i, const char* format = "%.6g") {
  if (!array.is_array() || i >= array.size()) return "-";
  return number(array[i], format);
}

std::string text(const json& object, const char* key) {
  const auto it = object.find(key);
  return it != object.end() && it->is_string() ? it->get<std::string>() : "-";
}

std::string flag(const json& object, const char* key, const char* yes, const char* no) {
  if (!object.is_object()) return "-";
  const auto it = object.find(key);
  if (it == object.end() || !it->is_boolean()) return "-";
  return it->get<bool>() ? yes : no;
}

std::string row(const char* format, auto... args) {
  char buffer[512];
  std::snprintf(buffer, sizeof(buffer), format, args...);
  return buffer;
}

}  // namespace

std::string format_status(const json& s) {
  const json empty = json::object();
  const json& loop = s.contains("loop") ? s["loop"] : empty;
  const json& lateness = loop.contains("lateness_us") ? loop["lateness_us"] : empty;
  const json& exec = loop.contains("exec_us") ? loop["exec_us"] : empty;
  const json& drv = s.contains("driver_stats") ? s["driver_stats"] : empty;
  std::string out;
  out += row("%-14s %s\n", "state", text(s, "state").c_str());
  if (s.contains("fault_reason"))
    out += row("%-14s %s\n", "fault", text(s, "fault_reason").c_str());
  if (s.contains("waiting_for_device"))
    out += row("%-14s %s\n", "waiting for", text(s, "waiting_for_device").c_str());
  out += row("%-14s %s, config %s\n", "release", text(s, "release").c_str(),
             s.contains("config_file") ? text(s, "config_file").c_str() : "(defaults)");
  out += row("%-14s %s s\n", "uptime", member(s, "uptime_s", "%.1f").c_str());
  out += row("%-14s %s s\n", "period", member(s, "period_s").c_str());
  out += row("%-14s %s, voltage %s V (%s), commanded %s V\n", "excitation",
             flag(s, "excitation", "on", "off").c_str(), member(s, "voltage", "%.4f").c_str(),
             s.contains("output") ? text(s, "output").c_str() : "?",
             member(s, "voltage_command", "%.4f").c_str());
  out += row("%-14s %s, overruns %s, missed periods %s\n", "cycles",
             member(loop, "cycles", "%.0f").c_str(), member(loop, "overruns", "%.0f").c_str(),
             member(loop, "missed_periods", "%.0f").c_str());
  out += row("%-14s min %s  mean %s  p99 %s  max %s\n", "lateness [us]",
             member(lateness, "min", "%.1f").c_str(), member(lateness, "mean", "%.1f").c_str(),
             member(lateness, "p99", "%.1f").c_str(), member(lateness, "max", "%.1f").c_str());
  out += row("%-14s mean %s  max %s\n", "exec [us]", member(exec, "mean", "%.1f").c_str(),
             member(exec, "max", "%.1f").c_str());
  out += row("%-14s %s, link %s\n", "driver", text(s, "driver").c_str(),
             flag(drv, "link_up", "up", "down").c_str());
  out += row("%-14s reads %s (errors %s), writes %s (errors %s), dropped %s, reconnects %s\n", "",
             member(drv, "reads", "%.0f").c_str(), member(drv, "read_errors", "%.0f").c_str(),
             member(drv, "writes", "%.0f").c_str(), member(drv, "write_errors", "%.0f").c_str(),
             member(drv, "dropped", "%.0f").c_str(), member(drv, "reconnects", "%.0f").c_str());
  if (s.contains("refine")) {
    const json& r = s["refine"];
    out += row("%-14s fits %s (converged %s), windows %s, last fit %s s, hand-off dropped %s\n",
               "refinement", member(r, "fits", "%.0f").c_str(),
               member(r, "converged_fits", "%.0f").c_str(), member(r, "windows", "%.0f").c_str(),
               member(r, "last_fit_duration_s", "%.3f").c_str(),
               member(r, "handoff_dropped", "%.0f").c_str());
  }
  return out;
}

namespace {

// A block's verdict in words, beside its σ (issue 28): a σ whose block failed its validation is
// never shown as if it could be trusted. "-" when the block was not validated.
std::string verdict_words(const json& validation, const char* block) {
  if (!validation.is_object() || !validation.contains(block)) return "-";
  const std::string verdict = text(validation[block], "verdict");
  if (verdict == "adequate") return "adequate";
  if (verdict == "noise_colored") return "sigma-at-risk";
  if (verdict == "structure") return "NOT-VALID";
  return verdict;  // untested
}

std::string validation_line(const char* who, const json& v) {
  std::string out = row("%s validation:", who);
  for (const char* block : {"mechanical", "thermal"}) {
    const json none;
    const json& b = v.contains(block) ? v[block] : none;
    out += row(" %s %s (%s, fit %s %%, noise ratio %s)", block, text(b, "verdict").c_str(),
               text(b, "decisive").c_str(), member(b, "fit_percent", "%.2f").c_str(),
               member(b, "noise_ratio", "%.3g").c_str());
  }
  return out + "\n";
}

}  // namespace

std::string format_estimate(const json& e) {
  const bool truth = e.contains("theta_true");
  const json none;
  const bool refined = e.contains("refined") && e["refined"].is_object();
  const json& r = refined ? e["refined"] : none;
  const std::string best = text(e, "best");
  std::string out = row("t = %s s, updates %s, skipped %s\n", member(e, "t", "%.3f").c_str(),
                        member(e, "updates", "%.0f").c_str(), member(e, "skipped", "%.0f").c_str());
  // Both estimates side by side; '*' marks the one the daemon recommends.
  const char* paper_head = best == "paper" ? "paper*" : "paper";
  const char* refined_head = best == "refined" ? "refined*" : "refined";
  const json& paper_v = e.contains("paper_validation") ? e["paper_validation"] : none;
  const json& refined_v = refined && r.contains("validation") ? r["validation"] : none;
  out += row("%-12s %14s %10s %13s", "parameter", paper_head, "sigma", "validation");
  if (refined) out += row(" %14s %10s %13s", refined_head, "sigma", "validation");
  if (truth) out += row(" %14s %10s", "true", "rel.error");
  if (truth && refined) out += row(" %10s", "refined");
  out += '\n';
  const json& theta_hat = e.contains("theta_hat") ? e["theta_hat"] : none;
  const json& sigma = e.contains("sigma") ? e["sigma"] : none;
  const json& theta_true = truth ? e["theta_true"] : none;
  const json& rel = e.contains("rel_error") ? e["rel_error"] : none;
  const json& r_hat = refined && r.contains("theta_hat") ? r["theta_hat"] : none;
  const json& r_sigma = refined && r.contains("sigma") ? r["sigma"] : none;
  const json& r_rel = refined && r.contains("rel_error") ? r["rel_error"] : none;
  for (std::size_t i = 0; i < kThetaNames.size(); ++i) {
    const char* block = i < 4 ? "mechanical" : "thermal";  // θ1..θ4, θ5..θ6
    out += row("%-12s %14s %10s %13s", kThetaNames[i], element(theta_hat, i, "%.7g").c_str(),
               element(sigma, i, "%.3g").c_str(), verdict_words(paper_v, block).c_str());
    if (refined)
      out += row(" %14s %10s %13s", element(r_hat, i, "%.7g").c_str(),
                 element(r_sigma, i, "%.3g").c_str(), verdict_words(refined_v, block).c_str());
    if (truth)
      out += row(" %14s %10s", element(theta_true, i, "%.7g").c_str(),
                 element(rel, i, "%.2e").c_str());
    if (truth && refined) out += row(" %10s", element(r_rel, i, "%.2e").c_str());
    out += '\n';
  }
  const json& biased = e.contains("paper_biased") ? e["paper_biased"] : none;
  out += row("best: %s; paper law biased: mechanical %s, thermal %s\n", best.c_str(),
             flag(biased, "mechanical", "yes", "no").c_str(),
             flag(biased, "thermal", "yes", "no").c_str());
  if (e.contains("best_reason")) out += "best_reason: " + text(e, "best_reason") + "\n";
  if (refined_v.is_object()) out += validation_line("refined", refined_v);
  if (paper_v.is_object()) out += validation_line("paper", paper_v);
  if (refined) {
    const json& w = r.contains("window") ? r["window"] : none;
    const json& fitted = r.contains("fitted_at") ? r["fitted_at"] : none;
    out +=
        row("refined: window [%s, %s] s (%s samples), fitted at t = %s s (%s), %s, %s "
            "iterations%s%s\n",
            member(w, "t_begin", "%.1f").c_str(), member(w, "t_end", "%.1f").c_str(),
            member(w, "samples", "%.0f").c_str(), member(fitted, "t", "%.1f").c_str(),
            fitted.is_object() ? text(fitted, "utc").c_str() : "-",
            flag(r, "converged", "converged", "NOT converged").c_str(),
            member(r, "iterations", "%.0f").c_str(), r.contains("message") ? ": " : "",
            r.contains("message") ? text(r, "message").c_str() : "");
  }
  const json& excitation = e.contains("excitation") ? e["excitation"] : none;
  const json& converged = e.contains("converged") ? e["converged"] : none;
  out += row("%-12s %10s %10s\n", "block", "excitation", "converged");
  for (const char* block : {"mechanical", "thermal"})
    out += row("%-12s %10s %10s\n", block, member(excitation, block, "%.3g").c_str(),
               flag(converged, block, "yes", "no").c_str());
  if (e.contains("physical")) {
    const json& p = e["physical"];
    out += "physical (from the configured m and R):\n";
    out += row("  b      = %s N*s/m\n", member(p, "b").c_str());
    out += row("  k      = %s N/m\n", member(p, "k").c_str());
    out += row("  alpha1 = %s N*s/(m*degC)\n", member(p, "alpha1").c_str());
    out += row("  alpha2 = %s N/degC\n", member(p, "alpha2").c_str());
    out += row("  lambda = %s W/degC\n", member(p, "lambda").c_str());
    out += row("  Cth    = %s J/degC\n", member(p, "Cth").c_str());
  }
  return out;
}

std::string format_estimate_line(const json& e) {
  const json none;
  const json& theta_hat = e.contains("theta_hat") ? e["theta_hat"] : none;
  std::string out = "t=" + member(e, "t", "%.3f") + " theta_hat=[";
  for (std::size_t i = 0; i < kThetaNames.size(); ++i) {
    if (i > 0) out += ' ';
    out += element(theta_hat, i, "%.7g");
  }
  out += "]";
  if (e.contains("refined") && e["refined"].contains("theta_hat")) {
    const json& r = e["refined"]["theta_hat"];
    out += " refined=[";
    for (std::size_t i = 0; i < kThetaNames.size(); ++i) {
      if (i > 0) out += ' ';
      out += element(r, i, "%.7g");
    }
    out += "]";
  }
  if (e.contains("best")) out += " best=" + text(e, "best");
  if (e.contains("refined") && e["refined"].contains("validation")) {
    const json& v = e["refined"]["validation"];
    out += " validation=" + verdict_words(v, "mechanical") + "/" + verdict_words(v, "thermal");
  }
  return out + "\n";
}

}  // namespace scp::daemon::ctl

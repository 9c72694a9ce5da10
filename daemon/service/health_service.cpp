#include "daemon/service/health_service.hpp"

#include <spdlog/spdlog.h>

#include <cstring>
#include <filesystem>

#include "common/clock.hpp"
#include "daemon/service/state/checkpoint.hpp"

namespace scp::daemon {

namespace {

using server::HealthOutcome;

// The latest converged refined window as the monitor published it, as a baseline; or why not.
std::optional<health::Baseline> from_view(const health::HealthView& v, std::string& why) {
  if (!v.fit_present) {
    why =
        "no converged refined estimate yet: wait for `refined.converged` in ESTIMATE "
        "(refine.min_window_s of running with excitation)";
    return std::nullopt;
  }
  const std::string verdict(v.fit_verdict.data());
  // `untested` (a window shorter than the thermal block's time scale) says nothing against the
  // model: the baseline keeps the verdict, and `baseline show` prints it.
  if (v.fit_validated && verdict != "adequate" && verdict != "untested") {
    why = "the refined estimate's validation is '" + verdict +
          "', not 'adequate': a baseline must describe the model well; see best_reason in "
          "ESTIMATE (docs/health.md)";
    return std::nullopt;
  }
  health::Baseline b;
  b.window.t_begin = v.fit_t_begin;
  b.window.t_end = v.fit_t_end;
  for (int i = 0; i < 6; ++i) {
    b.window.theta[i] = v.fit_theta[static_cast<std::size_t>(i)];
    for (int k = 0; k < 6; ++k)
      b.window.covariance(i, k) = v.fit_covariance[static_cast<std::size_t>(6 * i + k)];
  }
  b.verdict = verdict;
  return b;
}

}  // namespace

HealthService::HealthService(const config::DaemonConfig& cfg, std::string driver_name)
    : path_(baseline_path(cfg)),
      key_(baseline_key(cfg)),
      configured_file_(!cfg.health.baseline_file.empty()),
      actuator_(cfg.actuator.name),
      driver_(std::move(driver_name)),
      agent_(cfg.health.settings, link_, /*keep_events=*/false) {
  std::string warning;
  std::optional<health::Baseline> b = load_baseline(cfg, warning);
  if (b) {
    spdlog::info("health: baseline {} (saved for '{}', validation {})", path_, b->actuator,
                 b->verdict);
  } else if (configured_file_ || std::filesystem::exists(path_)) {
    spdlog::warn("health: {}", warning);
  } else {
    spdlog::info(
        "health: no baseline yet; `scp-estimatorctl baseline save` once the refined "
        "estimate has converged");
  }
  use(std::move(b));
  agent_.poll();  // the worker is not running yet: publish the start-up view now
}

void HealthService::use(std::optional<health::Baseline> baseline) {
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    baseline_ = baseline;
  }
  health::HealthCommand command;
  command.kind = health::HealthCommand::Kind::baseline;
  command.baseline = std::move(baseline);
  command.source = path_;
  link_.post(std::move(command));
}

nlohmann::json HealthService::baseline() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  if (!baseline_) return {{"present", false}, {"file", path_}};
  nlohmann::json out = nlohmann::json::parse(health::to_json(*baseline_));
  out["present"] = true;
  out["file"] = path_;
  return out;
}

HealthOutcome HealthService::save_baseline(double /*now_t*/) {
  HealthOutcome outcome;
  std::optional<health::Baseline> b = from_view(view(), outcome.message);
  if (!b) return outcome;
  b->actuator = actuator_;
  b->driver = driver_;
  b->saved_unix_ns = clock::unix_ns();
  try {
    state::write_state_file(path_, health::to_json(*b), kBaselineWhat, key_);
  } catch (const std::exception& e) {
    outcome.message = e.what();
    return outcome;
  }
  char text[160];
  std::snprintf(text, sizeof(text), "baseline saved to %s: the refined window [%.1f, %.1f] s",
                path_.c_str(), b->window.t_begin, b->window.t_end);
  use(std::move(b));
  return {true, text};
}

HealthOutcome HealthService::clear_baseline() {
  if (!configured_file_) {
    std::error_code ec;
    std::filesystem::remove(path_, ec);
    if (ec) return {false, "cannot remove " + path_ + ": " + ec.message()};
  }
  use(std::nullopt);
  return {true, configured_file_ ? "baseline unloaded (" + path_ +
                                       " is health.baseline.file, made elsewhere: kept)"
                                 : "baseline " + path_ + " removed; health monitoring is blind"};
}

HealthOutcome HealthService::acknowledge(double now_t) {
  const health::HealthView v = view();
  if (!v.baseline_present) return {false, "nothing to acknowledge: no baseline"};
  health::HealthCommand command;
  command.kind = health::HealthCommand::Kind::acknowledge;
  command.t = now_t;
  link_.post(std::move(command));
  return {true, std::string("acknowledged state ") + scp::health::state_name(v.report.state)};
}

}  // namespace scp::daemon

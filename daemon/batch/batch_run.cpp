#include "daemon/batch/batch_run.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <limits>
#include <memory>
#include <optional>

#include "common/clock.hpp"
#include "common/heap.hpp"
#include "daemon/analysis/health/health_agent.hpp"
#include "daemon/analysis/refine/refine_worker.hpp"
#include "daemon/analysis/refine/refiner.hpp"
#include "daemon/batch/parallel_refinement.hpp"
#include "daemon/config/binder.hpp"
#include "daemon/core/loop.hpp"
#include "daemon/outputs/recording/recorder.hpp"
#include "daemon/outputs/server/render.hpp"
#include "daemon/outputs/server/render_health.hpp"
#include "daemon/service/driver_factory.hpp"
#include "daemon/service/health_baseline.hpp"
#include "drivers/replay/replay_driver.hpp"

namespace scp::daemon {

namespace {

// The configured driver, or the replayed files in its place. A recording made with this
// configuration keeps its period, so that the estimator's gap threshold (max_gap_periods x
// nominal_period) is the live run's; a file from elsewhere sets its own (its median step).
std::unique_ptr<drivers::Driver> batch_driver(config::DaemonConfig& cfg,
                                              const BatchOptions& options,
                                              drivers::replay::ReplayDriver*& replay) {
  if (options.replay_paths.empty()) {
    if (cfg.driver.type == config::DriverType::modbus) {
      // No wall-clock deadline offline: wait as long as a lock-step peer needs.
      cfg.driver.modbus.response_timeout_s = cfg.driver.modbus.offline_response_timeout_s;
      cfg.driver.modbus.enforce_period_budget = false;
    }
    return make_driver(cfg);
  }
  auto replay_driver = std::make_unique<drivers::replay::ReplayDriver>(options.replay_paths);
  if (std::fabs(replay_driver->period() - cfg.loop.period_s) > 0.01 * cfg.loop.period_s) {
    cfg.loop.period_s = replay_driver->period();
    cfg.estimator.nominal_period = replay_driver->period();
  }
  replay = replay_driver.get();
  return replay_driver;
}

// Fits made at once: options.jobs, 0 meaning inline. Inline each warm refit starts from the fit
// just before; a lane's from N intervals back gives way to the full fit more often, and since the
// warm refits became the cheap case two lanes cost more CPU than they save in wall time
// (docs/numerics.md, "Offline on every core").
unsigned batch_jobs(const BatchOptions& options) {
  return std::max(1U, options.jobs);
}

// One batch run: the daemon's loop, cycle after cycle without sleeping, on loop time; the
// refinement inline between cycles or on worker threads beside them (the same fits every run);
// the recorder on its thread.
class BatchRun {
 public:
  BatchRun(config::DaemonConfig cfg, const BatchOptions& options);
  nlohmann::json run();

 private:
  void run_cycles();
  void refine_after_cycle(double t);
  void refine_at_end(double t_last);
  void refine_now(double t);
  void push_refined(const refine::RefinedView& view);
  void forward_rows();
  void start_refinement();
  void start_health();
  nlohmann::json summary(double wall_s) const;

  config::DaemonConfig cfg_;
  const BatchOptions& options_;
  drivers::replay::ReplayDriver* replay_ = nullptr;
  std::unique_ptr<drivers::Driver> driver_;
  // Heap-allocated: the seqlock and the rings are large, and this runs on the main thread's stack.
  std::unique_ptr<rt::Seqlock<PublishedState>> published_ =
      std::make_unique<rt::Seqlock<PublishedState>>();
  std::unique_ptr<CommandRing> commands_ = std::make_unique<CommandRing>();
  std::unique_ptr<RecordRing> record_ring_;
  std::unique_ptr<RefinedRing> refined_ring_;
  std::optional<Recorder> recorder_;
  std::unique_ptr<HandOffRing> handoff_;
  std::optional<refine::Refiner> refiner_;  // jobs 1: the fits inline
  std::unique_ptr<ParallelRefinement> parallel_;
  // With parallel fits and a recording, the loop's rows wait here until the fits made before
  // them are applied, so that each row carries the fit inline would have shown it.
  std::unique_ptr<RecordRing> staged_rows_;
  std::deque<RecordRow> held_rows_;
  // The health monitor, inline with the refinement; every event kept for the summary.
  std::unique_ptr<health::HealthLink> health_link_;
  std::unique_ptr<health::HealthAgent> health_;
  std::optional<Loop> loop_;
  double replay_start_ = 0.0;
  std::uint64_t cycles_ = 0;
};

BatchRun::BatchRun(config::DaemonConfig cfg, const BatchOptions& options)
    : cfg_(std::move(cfg)), options_(options) {
  driver_ = batch_driver(cfg_, options_, replay_);
  config::resolve_voltage_interval(cfg_.refine, driver_->stamps_voltage_instants());
  driver_->open();
  if (!options_.record_path.empty()) {
    record_ring_ = std::make_unique<RecordRing>();
    refined_ring_ = std::make_unique<RefinedRing>();
    recorder_.emplace(options_.record_path, *record_ring_, refined_ring_.get());
  }
  if (cfg_.refine.enabled) start_refinement();
  loop_.emplace(cfg_, *driver_, *published_, *commands_,
                staged_rows_ ? staged_rows_.get() : record_ring_.get(),
                /*block_when_record_full=*/true, handoff_.get());
}

void BatchRun::start_refinement() {
  handoff_ = std::make_unique<HandOffRing>();
  start_health();
  const unsigned jobs = batch_jobs(options_);
  if (jobs <= 1) {
    refiner_.emplace(cfg_.refine, cfg_.estimator, cfg_.loop.period_s);
    refiner_->set_observer(health_.get());
    return;
  }
  parallel_ = std::make_unique<ParallelRefinement>(
      cfg_, jobs, health_.get(), [this](const refine::RefinedView& v) { push_refined(v); });
  if (recorder_) staged_rows_ = std::make_unique<RecordRing>();
}

// The baseline file if there is one, else the run's first converged window of refine.window_s
// (less one period: a window's span is its samples' first to last instant).
void BatchRun::start_health() {
  health_link_ = std::make_unique<health::HealthLink>();
  health_ = std::make_unique<health::HealthAgent>(cfg_.health.settings, *health_link_,
                                                  /*keep_events=*/true);
  std::string warning;
  if (std::optional<health::Baseline> b = load_baseline(cfg_, warning)) {
    health_->runner().set_baseline(b, baseline_path(cfg_));
  } else if (!cfg_.health.baseline_file.empty()) {
    // A baseline the configuration names is wanted: the run's own start is no substitute.
    throw config::ConfigError("health.baseline.file: " + warning);
  } else {
    health_->runner().adopt_first_fit(cfg_.refine.window_s - cfg_.loop.period_s);
  }
}

nlohmann::json BatchRun::run() {
  const auto wall_start = std::chrono::steady_clock::now();
  run_cycles();
  const double wall_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
  if (recorder_) recorder_->finish();
  driver_->close();
  return summary(wall_s);
}

void BatchRun::run_cycles() {
  const double period = cfg_.loop.period_s;
  // A replay stops at the end of its file unless told to stop earlier.
  const double duration = options_.duration_s.value_or(
      replay_ == nullptr ? kDefaultBatchDuration : std::numeric_limits<double>::infinity());
  const std::uint64_t last = std::isfinite(duration)
                                 ? static_cast<std::uint64_t>(std::llround(duration / period))
                                 : std::numeric_limits<std::uint64_t>::max() - 1;
  if (replay_ != nullptr) replay_->next_time(replay_start_);
  double t_last = 0.0;
  for (cycles_ = 0; cycles_ <= last; ++cycles_) {
    drivers::CycleTime now{static_cast<double>(cycles_) * period, period};
    // A replay's cycles run at the recorded times, gaps included, as the live loop's did: the
    // staleness, stuck-sensor and excitation clocks then see what they saw live.
    if (replay_ != nullptr && replay_->next_time(now.t) &&
        now.t - replay_start_ > duration + 0.5 * period) {
      break;
    }
    if (loop_->cycle(now) == CycleResult::end_of_data) break;
    t_last = now.t;
    refine_after_cycle(now.t);
  }
  loop_->shutdown();
  refine_at_end(t_last);
}

void BatchRun::refine_after_cycle(double t) {
  if (refiner_) {
    refiner_->drain(*handoff_);
    if (refiner_->due()) refine_now(t);
  } else if (parallel_) {
    parallel_->after_cycle(*handoff_, t, refine::paper_estimate(published_->load()));
    forward_rows();
  }
}

void BatchRun::refine_at_end(double t_last) {
  if (refiner_) {
    refiner_->drain(*handoff_);
    if (refiner_->has_unfitted_data()) refine_now(t_last);  // the final window
  } else if (parallel_) {
    parallel_->finish(*handoff_, t_last, refine::paper_estimate(published_->load()));
  }
  forward_rows();
  // What the samples after the last fit raised, which no fit's poll will collect now.
  if (health_) health_->poll();
}

void BatchRun::refine_now(double t) {
  push_refined(refiner_->fit(refine::paper_estimate(published_->load()), t, clock::unix_ns()));
}

void BatchRun::push_refined(const refine::RefinedView& view) {
  if (refined_ring_) {
    while (!refined_ring_->try_push(view)) std::this_thread::yield();  // the recorder catches up
  }
}

// The rows no fit still under way precedes, to the recorder.
void BatchRun::forward_rows() {
  if (!staged_rows_) return;
  RecordRow row;
  while (staged_rows_->try_pop(row)) held_rows_.push_back(row);
  const std::optional<double> wait_from = parallel_->first_unapplied_t();
  while (!held_rows_.empty() && (!wait_from || held_rows_.front().t < *wait_from)) {
    while (!record_ring_->try_push(held_rows_.front())) std::this_thread::yield();
    held_rows_.pop_front();
  }
}

// The monitor's state at the end, and every change point and drift it raised.
void put_health(nlohmann::json& out, const health::HealthAgent& agent) {
  out["health"] = server::health_json(agent.runner().view(), /*full=*/false);
  nlohmann::json events = nlohmann::json::array();
  for (const scp::health::HealthEvent& e : agent.events()) {
    nlohmann::json item = {
        {"event", scp::health::event_name(e.kind)}, {"t", e.t}, {"text", health::describe(e)}};
    if (e.kind == scp::health::EventKind::changed) {
      item["onset"] = e.change.onset;
      item["detector"] = scp::health::detector_name(e.change.detector);
      const int p = e.change.parameter;
      if (p >= 0) {
        const auto& shift = e.change.parameters[static_cast<std::size_t>(p)];
        item["parameter"] = scp::health::kParameterNames[static_cast<std::size_t>(p)];
        item["relative"] = shift.relative;
        item["delta"] = shift.delta;
        item["sigma"] = shift.sigma;
      }
    }
    events.push_back(std::move(item));
  }
  out["health_events"] = std::move(events);
}

// ESTIMATE as a client would read it at the end (docs/protocol.md), and the run's own members.
nlohmann::json BatchRun::summary(double wall_s) const {
  const PublishedState last = published_->load();
  const refine::RefinedView* refined = refiner_    ? &refiner_->view()
                                       : parallel_ ? &parallel_->view()
                                                   : nullptr;
  nlohmann::json out = server::estimate_json(last.estimate, refined, last.uptime_s);
  out.erase("class");
  if (refined != nullptr) {
    out["refine"] = {{"fits", refined->fits},
                     {"converged_fits", refined->converged_fits},
                     {"warm_fits", refined->warm_fits},
                     {"windows", refined->windows},
                     {"handoff_dropped", last.handoff_dropped}};
  }
  out["state"] = to_string(last.state);
  if (last.fault_reason[0] != '\0') out["fault_reason"] = last.fault_reason.data();
  out["driver"] = std::string(driver_->name());
  out["cycles"] = cycles_;
  out["wall_time_s"] = wall_s;
  out["realtime_factor"] = wall_s > 0 ? (last.estimate.t - replay_start_) / wall_s : 0.0;
  if (replay_ != nullptr) {
    const drivers::replay::Trace& trace = replay_->trace();
    out["replay"] = {{"files", trace.files.size()},
                     {"rows", trace.rows.size()},
                     {"period_s", trace.period},
                     {"gaps", trace.gaps},
                     {"max_step_s", trace.max_step}};
  }
  if (recorder_) out["recorded_rows"] = recorder_->rows_written();
  if (health_) put_health(out, *health_);
  return out;
}

constexpr const char* kThetaNames[6] = {"theta1 b/m",  "theta2 a1/m",  "theta3 k/m",
                                        "theta4 a2/m", "theta5 l/Cth", "theta6 1/(R Cth)"};

// A number of the summary in `format`, "-" where it has none (a zero true θ has no relative
// error, a diverged estimate no finite value: both are null).
std::string number_or_dash(const nlohmann::json& v, const char* format) {
  if (!v.is_number()) return "-";
  char text[64];
  std::snprintf(text, sizeof text, format, v.get<double>());
  return text;
}

std::string refined_heading(const nlohmann::json& s) {
  const nlohmann::json& r = s["refined"];
  char line[240];
  std::snprintf(line, sizeof line,
                "refined: window [%.3f, %.3f] s, %s samples, %s after %s iterations (%s), "
                "fit %s of %s\n",
                r["window"].value("t_begin", 0.0), r["window"].value("t_end", 0.0),
                r["window"]["samples"].dump().c_str(),
                r.value("converged", false) ? "converged" : "NOT converged",
                r["iterations"].dump().c_str(), r.value("message", std::string()).c_str(),
                r["fits"].dump().c_str(), s["refine"]["fits"].dump().c_str());
  return line;
}

// The voltage's interval the fit used, and when it estimated it or weighed the declared one, how
// far the data decided it.
std::string interval_line(const nlohmann::json& r) {
  std::string out = "voltage interval: " + r.value("voltage_interval", std::string("-"));
  if (r.contains("voltage_interval_test")) {
    const nlohmann::json& t = r["voltage_interval_test"];
    const char* how = !t.value("declared", false)      ? "estimated"
                      : t.value("contradicted", false) ? "declared, CONTRADICTED by the data"
                                                       : "declared, checked";
    char line[200];
    std::snprintf(line, sizeof line, " (%s: fitted %s, criterion difference %s, threshold %s)", how,
                  t.value("fitted", std::string("-")).c_str(),
                  number_or_dash(t.value("statistic", nlohmann::json()), "%.3g").c_str(),
                  number_or_dash(t.value("threshold", nlohmann::json()), "%.3g").c_str());
    out += line;
    if (t.value("joint", false)) {
      std::snprintf(line, sizeof line, "; from x and T together%s (T alone: %s)",
                    t.value("joint_lag_held", false) ? ", the sensor lag held at 0" : "",
                    number_or_dash(t.value("thermal_statistic", nlohmann::json()), "%.3g").c_str());
      out += line;
    }
    if (t.contains("equivalent")) {
      std::snprintf(line, sizeof line, "; under the other interval theta moved %s sigma: %s",
                    number_or_dash(t.value("theta_shift_sigma", nlohmann::json()), "%.2g").c_str(),
                    t.value("equivalent", false) ? "equivalent" : "it matters");
      out += line;
    }
  }
  return out + "\n";
}

// One estimate's validation (ESTIMATE refined.validation or paper_validation), a line per block:
// the verdict, the decisive test, fit % and the noise ratio.
std::string validation_lines(const char* who, const nlohmann::json& v) {
  std::string out;
  for (const char* block : {"mechanical", "thermal"}) {
    const nlohmann::json& b = v[block];
    char line[240];
    std::snprintf(line, sizeof line, "%s validation %s: %s (%s), fit %s %%, noise ratio %s\n", who,
                  block, b.value("verdict", std::string("-")).c_str(),
                  b.value("decisive", std::string("-")).c_str(),
                  number_or_dash(b.value("fit_percent", nlohmann::json()), "%.2f").c_str(),
                  number_or_dash(b.value("noise_ratio", nlohmann::json()), "%.3g").c_str());
    out += line;
  }
  return out;
}

// The paper law's θ̂ beside the refined one, and which the daemon recommends.
std::string refined_table(const nlohmann::json& s) {
  const nlohmann::json& r = s["refined"];
  const bool truth = r.contains("rel_error");
  std::string out = refined_heading(s);
  char line[240];
  if (truth) {
    std::snprintf(line, sizeof line, "%-18s %16s %12s %12s %12s\n", "parameter", "refined",
                  "rel.error", "sigma", "paper rel.");
  } else {
    std::snprintf(line, sizeof line, "%-18s %16s %12s %16s\n", "parameter", "refined", "sigma",
                  "paper");
  }
  out += line;
  for (std::size_t i = 0; i < 6; ++i) {
    const std::string hat = number_or_dash(r["theta_hat"][i], "%16.9g");
    const std::string sigma = number_or_dash(r["sigma"][i], "%12.3e");
    if (truth) {
      std::snprintf(line, sizeof line, "%-18s %16s %12s %12s %12s\n", kThetaNames[i], hat.c_str(),
                    number_or_dash(r["rel_error"][i], "%12.3e").c_str(), sigma.c_str(),
                    number_or_dash(s["rel_error"][i], "%12.3e").c_str());
    } else {
      std::snprintf(line, sizeof line, "%-18s %16s %12s %16s\n", kThetaNames[i], hat.c_str(),
                    sigma.c_str(), number_or_dash(s["theta_hat"][i], "%16.9g").c_str());
    }
    out += line;
  }
  std::snprintf(line, sizeof line, "paper law biased: mechanical %s, thermal %s; best: %s\n",
                s["paper_biased"].value("mechanical", false) ? "yes" : "no",
                s["paper_biased"].value("thermal", false) ? "yes" : "no",
                s["best"].get<std::string>().c_str());
  out += line;
  out += interval_line(r);
  if (r.contains("validation")) out += validation_lines("refined", r["validation"]);
  if (s.contains("paper_validation")) out += validation_lines("paper", s["paper_validation"]);
  if (s.contains("best_reason"))
    out += "best_reason: " + s["best_reason"].get<std::string>() + "\n";
  return out;
}

// The monitor's final state and every event, one line each.
std::string health_lines(const nlohmann::json& s) {
  std::string out = "health: " + s["health"].value("state", std::string("-")) + "\n";
  for (const nlohmann::json& e : s.value("health_events", nlohmann::json::array()))
    out += "  " + e.value("text", std::string()) + "\n";
  return out;
}

}  // namespace

nlohmann::json run_batch(config::DaemonConfig cfg, const BatchOptions& options) {
  // As the service's memory set-up does: the refinement's passes reuse their buffers.
  keep_freed_memory();
  return BatchRun(std::move(cfg), options).run();
}

std::string summary_table(const nlohmann::json& s) {
  std::string out;
  char line[200];
  const bool truth = s.contains("theta_true");
  std::snprintf(line, sizeof line, "t = %.3f s, state %s, %s driver, %.0fx real time\n",
                s.value("t", 0.0), s["state"].get<std::string>().c_str(),
                s["driver"].get<std::string>().c_str(), s["realtime_factor"].get<double>());
  out += line;
  if (truth) {
    std::snprintf(line, sizeof line, "%-18s %16s %16s %12s %12s\n", "parameter", "theta",
                  "theta_hat", "rel.error", "sigma");
  } else {
    std::snprintf(line, sizeof line, "%-18s %16s %12s\n", "parameter", "theta_hat", "sigma");
  }
  out += line;
  for (std::size_t i = 0; i < 6; ++i) {
    const std::string hat = number_or_dash(s["theta_hat"][i], "%16.9g");
    const std::string sigma = number_or_dash(s["sigma"][i], "%12.3e");
    if (truth) {
      std::snprintf(line, sizeof line, "%-18s %16s %16s %12s %12s\n", kThetaNames[i],
                    number_or_dash(s["theta_true"][i], "%16.9g").c_str(), hat.c_str(),
                    number_or_dash(s["rel_error"][i], "%12.3e").c_str(), sigma.c_str());
    } else {
      std::snprintf(line, sizeof line, "%-18s %16s %12s\n", kThetaNames[i], hat.c_str(),
                    sigma.c_str());
    }
    out += line;
  }
  if (s.contains("refined")) out += refined_table(s);
  if (s.contains("health")) out += health_lines(s);
  return out;
}

}  // namespace scp::daemon

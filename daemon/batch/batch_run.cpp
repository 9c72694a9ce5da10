#include "daemon/batch/batch_run.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <optional>
#include <thread>

#include "common/clock.hpp"
#include "daemon/analysis/refine/refine_worker.hpp"
#include "daemon/analysis/refine/refiner.hpp"
#include "daemon/core/loop.hpp"
#include "daemon/outputs/recording/recorder.hpp"
#include "daemon/outputs/server/render.hpp"
#include "daemon/service/driver_factory.hpp"
#include "drivers/replay/replay_driver.hpp"

namespace scp::daemon {

nlohmann::json run_batch(config::DaemonConfig cfg, const BatchOptions& options) {
  std::unique_ptr<drivers::Driver> driver;
  drivers::replay::ReplayDriver* replay = nullptr;
  if (!options.replay_paths.empty()) {
    auto replay_driver = std::make_unique<drivers::replay::ReplayDriver>(options.replay_paths);
    // A recording made with this configuration keeps its period, so that the estimator's gap
    // threshold (max_gap_periods x nominal_period) is the live run's; a file from elsewhere sets
    // its own (its median step).
    if (std::fabs(replay_driver->period() - cfg.loop.period_s) > 0.01 * cfg.loop.period_s) {
      cfg.loop.period_s = replay_driver->period();
      cfg.estimator.nominal_period = replay_driver->period();
    }
    replay = replay_driver.get();
    driver = std::move(replay_driver);
  } else {
    if (cfg.driver.type == config::DriverType::modbus) {
      // No wall-clock deadline offline: wait as long as a lock-step peer needs.
      cfg.driver.modbus.response_timeout_s = cfg.driver.modbus.offline_response_timeout_s;
      cfg.driver.modbus.enforce_period_budget = false;
    }
    driver = make_driver(cfg);
  }
  driver->open();

  // Heap-allocated: the seqlock and the rings are large, and this runs on the main thread's stack.
  auto published = std::make_unique<rt::Seqlock<PublishedState>>();
  auto commands = std::make_unique<CommandRing>();
  std::unique_ptr<RecordRing> ring;
  std::unique_ptr<RefinedRing> refined_ring;
  std::optional<Recorder> recorder;
  if (!options.record_path.empty()) {
    ring = std::make_unique<RecordRing>();
    refined_ring = std::make_unique<RefinedRing>();
    recorder.emplace(options.record_path, *ring, refined_ring.get());
  }
  // The refinement runs inline between cycles, on loop time: the same fits every run.
  std::unique_ptr<HandOffRing> handoff;
  std::optional<refine::Refiner> refiner;
  if (cfg.refine.enabled) {
    handoff = std::make_unique<HandOffRing>();
    refiner.emplace(cfg.refine, cfg.estimator, cfg.loop.period_s);
  }
  Loop loop(cfg, *driver, *published, *commands, ring.get(), /*block_when_record_full=*/true,
            handoff.get());
  auto refine_now = [&](double t) {
    const refine::RefinedView& view =
        refiner->fit(refine::paper_estimate(published->load()), t, clock::unix_ns());
    if (refined_ring) {
      while (!refined_ring->try_push(view)) std::this_thread::yield();  // the recorder catches up
    }
  };

  const double period = cfg.loop.period_s;
  // A replay stops at the end of its file unless told to stop earlier.
  const double duration = options.duration_s.value_or(
      replay == nullptr ? kDefaultBatchDuration : std::numeric_limits<double>::infinity());
  const std::uint64_t cycles = std::isfinite(duration)
                                   ? static_cast<std::uint64_t>(std::llround(duration / period))
                                   : std::numeric_limits<std::uint64_t>::max() - 1;
  double replay_start = 0.0;
  if (replay != nullptr) replay->next_time(replay_start);
  const auto wall_start = std::chrono::steady_clock::now();
  std::uint64_t k = 0;
  double t_last = 0.0;
  for (; k <= cycles; ++k) {
    drivers::CycleTime now{static_cast<double>(k) * period, period};
    // A replay's cycles run at the recorded times, gaps included, as the live loop's did: the
    // staleness, stuck-sensor and excitation clocks then see what they saw live.
    if (replay != nullptr && replay->next_time(now.t) &&
        now.t - replay_start > duration + 0.5 * period) {
      break;
    }
    if (loop.cycle(now) == CycleResult::end_of_data) break;
    t_last = now.t;
    if (refiner) {
      refiner->drain(*handoff);
      if (refiner->due()) refine_now(now.t);
    }
  }
  loop.shutdown();
  if (refiner) {
    refiner->drain(*handoff);
    if (refiner->has_unfitted_data()) refine_now(t_last);  // the final window
  }
  const double wall_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
  if (recorder) recorder->finish();
  driver->close();

  const PublishedState last = published->load();
  const EstimateView& e = last.estimate;
  nlohmann::json out;
  out["t"] = e.t;
  out["theta_hat"] = e.theta_hat;
  out["sigma"] = e.sigma;
  if (e.has_truth) {
    out["theta_true"] = e.theta_true;
    std::array<double, 6> rel{};
    for (std::size_t i = 0; i < 6; ++i) {
      rel[i] = std::fabs(e.theta_hat[i] - e.theta_true[i]) / std::fabs(e.theta_true[i]);
    }
    out["rel_error"] = rel;
  }
  if (e.has_physical) {
    out["physical"] = {{"b", e.physical[0]},      {"k", e.physical[1]},
                       {"alpha1", e.physical[2]}, {"alpha2", e.physical[3]},
                       {"lambda", e.physical[4]}, {"Cth", e.physical[5]}};
  }
  out["eps"] = e.eps;
  out["excitation"] = {{"mechanical", e.excitation[0]}, {"thermal", e.excitation[1]}};
  out["converged"] = {{"mechanical", e.converged[0]}, {"thermal", e.converged[1]}};
  server::put_refinement(out, e, refiner ? &refiner->view() : nullptr, last.uptime_s);
  if (refiner) {
    out["refine"] = {{"fits", refiner->view().fits},
                     {"converged_fits", refiner->view().converged_fits},
                     {"windows", refiner->view().windows},
                     {"handoff_dropped", last.handoff_dropped}};
  }
  out["state"] = to_string(last.state);
  if (last.fault_reason[0] != '\0') out["fault_reason"] = last.fault_reason.data();
  out["driver"] = std::string(driver->name());
  out["cycles"] = k;
  out["updates"] = e.updates;
  out["skipped"] = e.skipped;
  out["wall_time_s"] = wall_s;
  out["realtime_factor"] = wall_s > 0 ? (e.t - replay_start) / wall_s : 0.0;
  if (replay != nullptr) {
    const drivers::replay::Trace& trace = replay->trace();
    out["replay"] = {{"files", trace.files.size()},
                     {"rows", trace.rows.size()},
                     {"period_s", trace.period},
                     {"gaps", trace.gaps},
                     {"max_step_s", trace.max_step}};
  }
  if (recorder) out["recorded_rows"] = recorder->rows_written();
  return out;
}

namespace {

std::string number_or_dash(const nlohmann::json& v, const char* format) {
  if (!v.is_number()) return "-";
  char text[64];
  std::snprintf(text, sizeof text, format, v.get<double>());
  return text;
}

// The paper law's θ̂ beside the refined one, and which the daemon recommends.
std::string refined_table(const nlohmann::json& s) {
  static const char* names[6] = {"theta1 b/m",  "theta2 a1/m",  "theta3 k/m",
                                 "theta4 a2/m", "theta5 l/Cth", "theta6 1/(R Cth)"};
  const nlohmann::json& r = s["refined"];
  const bool truth = r.contains("rel_error");
  std::string out;
  char line[240];
  std::snprintf(line, sizeof line,
                "refined: window [%.3f, %.3f] s, %s samples, %s after %s iterations (%s), "
                "fit %s of %s\n",
                r["window"].value("t_begin", 0.0), r["window"].value("t_end", 0.0),
                r["window"]["samples"].dump().c_str(),
                r.value("converged", false) ? "converged" : "NOT converged",
                r["iterations"].dump().c_str(), r.value("message", std::string()).c_str(),
                r["fits"].dump().c_str(), s["refine"]["fits"].dump().c_str());
  out += line;
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
      std::snprintf(line, sizeof line, "%-18s %16s %12s %12s %12s\n", names[i], hat.c_str(),
                    number_or_dash(r["rel_error"][i], "%12.3e").c_str(), sigma.c_str(),
                    number_or_dash(s["rel_error"][i], "%12.3e").c_str());
    } else {
      std::snprintf(line, sizeof line, "%-18s %16s %12s %16s\n", names[i], hat.c_str(),
                    sigma.c_str(), number_or_dash(s["theta_hat"][i], "%16.9g").c_str());
    }
    out += line;
  }
  std::snprintf(line, sizeof line, "paper law biased: mechanical %s, thermal %s; best: %s\n",
                s["paper_biased"].value("mechanical", false) ? "yes" : "no",
                s["paper_biased"].value("thermal", false) ? "yes" : "no",
                s["best"].get<std::string>().c_str());
  out += line;
  return out;
}

}  // namespace

std::string summary_table(const nlohmann::json& s) {
  static const char* names[6] = {"theta1 b/m",  "theta2 a1/m",  "theta3 k/m",
                                 "theta4 a2/m", "theta5 l/Cth", "theta6 1/(R Cth)"};
  std::string out;
  char line[200];
  const bool truth = s.contains("theta_true");
  std::snprintf(line, sizeof line, "t = %.3f s, state %s, %s driver, %.0fx real time\n",
                s["t"].get<double>(), s["state"].get<std::string>().c_str(),
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
    const double hat = s["theta_hat"][i].get<double>();
    const double sigma = s["sigma"][i].get<double>();
    if (truth) {
      std::snprintf(line, sizeof line, "%-18s %16.9g %16.9g %12.3e %12.3e\n", names[i],
                    s["theta_true"][i].get<double>(), hat, s["rel_error"][i].get<double>(), sigma);
    } else {
      std::snprintf(line, sizeof line, "%-18s %16.9g %12.3e\n", names[i], hat, sigma);
    }
    out += line;
  }
  if (s.contains("refined")) out += refined_table(s);
  return out;
}

}  // namespace scp::daemon

#include "daemon/batch_run.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>

#include "daemon/driver_factory.hpp"
#include "daemon/loop.hpp"
#include "daemon/recorder.hpp"
#include "drivers/replay/replay_driver.hpp"

namespace scp::daemon {

nlohmann::json run_batch(config::DaemonConfig cfg, const BatchOptions& options) {
  std::unique_ptr<drivers::Driver> driver;
  if (!options.replay_path.empty()) {
    auto replay = std::make_unique<drivers::replay::ReplayDriver>(options.replay_path);
    // The file sets the sample period; the estimator must use the same one.
    cfg.loop.period_s = replay->period();
    cfg.estimator.nominal_period = replay->period();
    driver = std::move(replay);
  } else {
    if (cfg.driver.type == "modbus") {
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
  std::optional<Recorder> recorder;
  if (!options.record_path.empty()) {
    ring = std::make_unique<RecordRing>();
    recorder.emplace(options.record_path, *ring);
  }
  Loop loop(cfg, *driver, *published, *commands, ring.get(), /*block_when_record_full=*/true);

  const double period = cfg.loop.period_s;
  const auto cycles = static_cast<std::uint64_t>(std::llround(options.duration_s / period));
  const auto wall_start = std::chrono::steady_clock::now();
  std::uint64_t k = 0;
  for (; k <= cycles; ++k) {
    const drivers::CycleTime now{static_cast<double>(k) * period, period};
    if (loop.cycle(now) == CycleResult::end_of_data) break;
  }
  loop.shutdown();
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
  out["state"] = to_string(last.state);
  if (last.fault_reason[0] != '\0') out["fault_reason"] = last.fault_reason.data();
  out["driver"] = std::string(driver->name());
  out["cycles"] = k;
  out["updates"] = e.updates;
  out["skipped"] = e.skipped;
  out["wall_time_s"] = wall_s;
  out["realtime_factor"] = wall_s > 0 ? e.t / wall_s : 0.0;
  if (recorder) out["recorded_rows"] = recorder->rows_written();
  return out;
}

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
  return out;
}

}  // namespace scp::daemon

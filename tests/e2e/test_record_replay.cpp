// Issue 10, "Done when": a real-time run with config/sim.yaml records rotating files; the rows'
// UTC times are monotonic across the files and the files replay (`--offline --replay DIR`) to the
// live run's θ̂.
//
// Run length: 40 s by default (CI). SCP_RECORD_REPLAY_S=600 runs the 10-minute check by hand
// (scripts/record-check); the figures it prints are in docs/recording.md.

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <sstream>

#include "tests/e2e/e2e_util.hpp"
#include "tests/support/recording_files.hpp"

namespace scp::test {
namespace {

// config/sim.yaml as JSON, so that only the test-local keys are replaced. A quoted scalar stays a
// string (socket.mode "0660"); a plain one is a bool, a number or a string.
json to_json(const YAML::Node& node) {
  if (node.IsMap()) {
    json out = json::object();
    for (const auto& item : node) out[item.first.as<std::string>()] = to_json(item.second);
    return out;
  }
  if (node.IsSequence()) {
    json out = json::array();
    for (const auto& item : node) out.push_back(to_json(item));
    return out;
  }
  if (node.IsNull()) return nullptr;
  const std::string text = node.as<std::string>();
  if (node.Tag() == "!") return text;
  if (text == "true") return true;
  if (text == "false") return false;
  try {
    std::size_t used = 0;
    const long long whole = std::stoll(text, &used);
    if (used == text.size()) return whole;
    const double value = std::stod(text, &used);
    if (used == text.size()) return value;
  } catch (const std::exception&) {
  }
  return text;
}

struct Row {
  double t = 0.0;
  std::int64_t unix_ns = 0;
  std::array<double, 6> theta_hat{};
};

struct Recording {
  std::vector<Row> rows;
  std::size_t files = 0;
  std::size_t missing_marks = 0;  // "# N rows missing" lines
};

// Reads the rows of every .csv in `directory`, in name order, checking on the way that t and the
// UTC time increase across the files.
Recording read_recording(const std::string& directory) {
  std::vector<std::string> files;
  for (const auto& entry : std::filesystem::directory_iterator(directory))
    if (entry.path().extension() == ".csv") files.push_back(entry.path().string());
  std::sort(files.begin(), files.end());
  Recording out;
  out.files = files.size();
  for (const auto& f : files) {
    std::istringstream in(read_text(f));
    std::string line;
    EXPECT_TRUE(std::getline(in, line)) << f;
    const auto header = split_csv(line);
    auto col = [&](const std::string& name) {
      const auto it = std::find(header.begin(), header.end(), name);
      EXPECT_NE(it, header.end()) << f << ": no column " << name;
      return static_cast<std::size_t>(it - header.begin());
    };
    const std::size_t t_col = col("t");
    const std::size_t ns_col = col("unix_ns");
    const std::size_t theta_col = col("theta_hat1");
    while (std::getline(in, line)) {
      if (line.rfind('#', 0) == 0) {
        ++out.missing_marks;
        continue;
      }
      const auto fields = split_csv(line);
      if (fields.size() != header.size()) {
        ADD_FAILURE() << f << ": " << line;
        continue;
      }
      Row r;
      r.t = std::stod(fields[t_col]);
      r.unix_ns = std::stoll(fields[ns_col]);
      for (std::size_t i = 0; i < 6; ++i) r.theta_hat[i] = std::stod(fields[theta_col + i]);
      if (!out.rows.empty()) {
        EXPECT_GT(r.t, out.rows.back().t) << f << ": loop time not increasing at " << line;
        EXPECT_GT(r.unix_ns, out.rows.back().unix_ns) << f << ": UTC not increasing at " << line;
      }
      out.rows.push_back(r);
    }
  }
  return out;
}

double run_seconds() {
  const char* env = std::getenv("SCP_RECORD_REPLAY_S");
  return env != nullptr ? std::stod(env) : 40.0;
}

TEST(RecordReplay, RealTimeRecordingReplaysToTheLiveEstimate) {
  const double seconds = run_seconds();
  TempDir dir;
  const std::string rec = dir.file("rec");
  std::filesystem::create_directory(rec);
  json sim = to_json(YAML::LoadFile(std::string(SCP_E2E_SOURCE_DIR) + "/config/sim.yaml"));
  // Test-local: socket, state and recording in `dir`; no socket group (the test user has none);
  // ordinary scheduling and no memory locking on this shared machine (the loop's timing code is
  // the same, it only misses more periods, which is what the replay must cope with).
  sim =
      merge_config(sim, {{"socket", {{"path", dir.file("d.sock")}, {"group", ""}}},
                         {"state", {{"directory", dir.file("state")}}},
                         {"loop", {{"realtime", {{"priority", 0}, {"lock_memory", false}}}}},
                         {"recording",
                          {{"directory", rec},
                           {"rotate_size_mib", seconds > 100 ? 16.0 : 2.0},  // ~0.45 MiB/s at 1 kHz
                           {"rotate_interval_s", 0.0},
                           {"keep_files", 0}}}});
  DaemonProcess daemon(dir, sim);
  daemon.start();
  sleep_s(seconds / 2);
  const json mid = daemon.estimate();  // what a client saw; the recording must hold the same θ̂
  sleep_s(seconds / 2);
  const json status = daemon.status();
  daemon.signal(SIGTERM);
  ASSERT_EQ(daemon.wait_exit(Seconds(30)), std::optional<int>(0)) << daemon.stderr_text();

  const Recording live = read_recording(rec);
  ASSERT_GE(live.files, 3u) << "expected several rotated files";
  ASSERT_GT(live.rows.size(), static_cast<std::size_t>(0.5 * seconds * 1000.0));
  const auto dropped = status["recording"].value("dropped_rows", std::uint64_t{0});
  EXPECT_EQ(live.missing_marks, 0u)
      << "rows dropped (" << dropped << "): the replay cannot reproduce the run";
  std::size_t gaps = 0;
  double max_step = 0.0;
  for (std::size_t i = 1; i < live.rows.size(); ++i) {
    const double step = live.rows[i].t - live.rows[i - 1].t;
    if (step > 1.5e-3) ++gaps;
    max_step = std::max(max_step, step);
  }

  // The client's ESTIMATE is the row of the same loop time.
  const double mid_t = num(mid, "t");
  const auto at =
      std::find_if(live.rows.begin(), live.rows.end(), [&](const Row& r) { return r.t == mid_t; });
  ASSERT_NE(at, live.rows.end()) << "no recorded row at the ESTIMATE's t " << mid_t;
  for (std::size_t i = 0; i < 6; ++i)
    EXPECT_EQ(at->theta_hat[i], mid["theta_hat"][i].get<double>()) << "theta_hat" << i + 1;

  // Replay the directory as it is, with the same configuration, recording the replay's rows.
  const std::string replayed = dir.file("replayed.csv");
  const ProcessResult r =
      run_process({estimatord_path(), "--config", daemon.config_path(), "--offline", "--json",
                   "--replay", rec, "--record", replayed},
                  Seconds(seconds * 4 + 120));
  ASSERT_EQ(r.exit_code, 0) << r.err << r.out;
  const json summary = json::parse(r.out);  // --json: one line
  EXPECT_EQ(summary["replay"]["files"].get<std::size_t>(), live.files);
  EXPECT_EQ(summary["replay"]["rows"].get<std::size_t>(), live.rows.size());
  EXPECT_EQ(summary["replay"]["gaps"].get<std::size_t>(), gaps);

  // The bound: the replay feeds the estimator the same doubles (written shortest-round-trip) at
  // the same t, through the same code, so θ̂ must agree to rounding; σ (the estimator's own
  // uncertainty, ≥ 1e-6 relative here) is many orders larger. Measured: identical, bit for bit.
  const Row& last = live.rows.back();
  double worst = 0.0;
  for (std::size_t i = 0; i < 6; ++i) {
    const double a = last.theta_hat[i];
    const double b = summary["theta_hat"][i].get<double>();
    const double rel = std::fabs(a - b) / std::max(std::fabs(a), 1e-300);
    worst = std::max(worst, rel);
    EXPECT_LE(rel, 1e-12) << "theta_hat" << i + 1 << ": live " << a << ", replay " << b;
  }
  // Every row, not only the last.
  std::istringstream in(read_text(replayed));
  std::string line;
  std::getline(in, line);
  std::size_t k = 0;
  double worst_row = 0.0;
  while (std::getline(in, line) && k < live.rows.size()) {
    const auto fields = split_csv(line);
    ASSERT_EQ(std::stod(fields[0]), live.rows[k].t) << "replayed row " << k;
    for (std::size_t i = 0; i < 6; ++i) {
      const double a = live.rows[k].theta_hat[i];
      const double b = std::stod(fields[6 + i]);
      worst_row = std::max(worst_row, std::fabs(a - b) / std::max(std::fabs(a), 1e-300));
    }
    ++k;
  }
  EXPECT_EQ(k, live.rows.size());
  EXPECT_LE(worst_row, 1e-12);

  const double lateness_max = status["loop"]["lateness_us"].value("max", -1.0);
  std::cout << "record-replay: " << seconds << " s real time, " << live.rows.size() << " rows in "
            << live.files << " files, dropped " << dropped << ", gaps " << gaps << ", longest step "
            << max_step << " s, missed periods " << loop_count(status, "missed_periods")
            << ", overruns " << loop_count(status, "overruns") << ", lateness max " << lateness_max
            << " us; replay " << num(summary, "wall_time_s") << " s; theta_hat max rel. diff: last "
            << worst << ", any row " << worst_row << "\n";
}

}  // namespace
}  // namespace scp::test

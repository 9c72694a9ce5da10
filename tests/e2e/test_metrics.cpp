// Issue 10, metrics: `scp-estimatorctl metrics` and the daemon's textfile (metrics section) are
// Prometheus text that `promtool check metrics` (Debian's prometheus package) accepts, and they
// carry what STATUS and ESTIMATE say. Without promtool the test fails under CI=true.

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <regex>

#include "tests/e2e/e2e_util.hpp"

namespace scp::test {
namespace {

std::string promtool_path() {
  for (const char* candidate : {"/usr/bin/promtool", "/usr/local/bin/promtool"})
    if (::access(candidate, X_OK) == 0) return candidate;
  return {};
}

// promtool check metrics reads stdin; exit 0 and no output = clean.
ProcessResult promtool_check(const std::string& promtool, const std::string& file) {
  return run_process({"/bin/sh", "-c", "\"$0\" check metrics < \"$1\"", promtool, file});
}

// The value of the sample whose line starts with `series` (name and labels), NaN if none.
double sample_value(const std::string& text, const std::string& series) {
  const auto at = text.find("\n" + series + " ");
  if (at == std::string::npos) return NAN;
  return std::strtod(text.c_str() + at + series.size() + 2, nullptr);
}

class Metrics : public ::testing::Test {
 protected:
  void SetUp() override {
    promtool_ = promtool_path();
    if (promtool_.empty()) {
      const char* ci = std::getenv("CI");
      if (ci != nullptr && std::string(ci) == "true")
        FAIL() << "promtool not found: apt-get install prometheus (scripts/setup)";
      GTEST_SKIP() << "promtool not found (apt-get install prometheus)";
    }
  }
  std::string promtool_;
};

// promtool must be able to fail here, or a pass means nothing: a counter without _total and a
// metric without HELP are lint problems.
TEST_F(Metrics, PromtoolRejectsABadExposition) {
  TempDir dir;
  write_text(dir.file("bad.prom"), "# TYPE requests counter\nrequests 1\n");
  const ProcessResult bad = promtool_check(promtool_, dir.file("bad.prom"));
  EXPECT_NE(bad.exit_code, 0) << bad.out << bad.err;
}

TEST_F(Metrics, CtlAndTextfileArePromtoolCleanAndTellTheTruth) {
  TempDir dir;
  const std::string textfiles = dir.file("textfiles");
  std::filesystem::create_directory(textfiles);
  DaemonProcess daemon(dir,
                       {{"actuator", {{"name", "bench-a"}}},
                        {"metrics", {{"textfile_directory", textfiles}, {"interval_s", 1.0}}}});
  daemon.start();
  ASSERT_TRUE(daemon.wait_status(
      [](const json& s) { return s.value("state", "") == "running" && num(s, "uptime_s") > 1.2; },
      Seconds(10)));
  EXPECT_EQ(daemon.status().value("actuator", ""), "bench-a");

  const ProcessResult ctl = daemon.run_ctl({"metrics"});
  ASSERT_EQ(ctl.exit_code, 0) << ctl.err;
  write_text(dir.file("ctl.prom"), ctl.out);
  const ProcessResult checked = promtool_check(promtool_, dir.file("ctl.prom"));
  EXPECT_EQ(checked.exit_code, 0) << checked.out << checked.err << "\n" << ctl.out;
  EXPECT_EQ(checked.out + checked.err, "");

  const std::string& m = ctl.out;
  EXPECT_EQ(sample_value(m, R"(scp_estimator_state{actuator="bench-a",state="running"})"), 1.0)
      << m;
  EXPECT_EQ(sample_value(m, R"(scp_estimator_state{actuator="bench-a",state="fault"})"), 0.0);
  EXPECT_EQ(sample_value(m, R"(scp_estimator_faults_total{actuator="bench-a"})"), 0.0);
  // θ̂ of the paper's law (not converged yet after a second: only present and finite).
  const double b_over_m = sample_value(
      m, R"(scp_estimator_theta{actuator="bench-a",estimator="paper",parameter="b_over_m"})");
  EXPECT_TRUE(std::isfinite(b_over_m)) << m;
  EXPECT_FALSE(std::isnan(sample_value(
      m,
      R"(scp_estimator_theta_sigma{actuator="bench-a",estimator="paper",parameter="inv_r_cth"})")));
  // The lateness histogram's +Inf bucket equals its count and the loop's cycles are counted.
  const double inf_bucket = sample_value(
      m, R"(scp_estimator_loop_lateness_seconds_bucket{actuator="bench-a",le="+Inf"})");
  EXPECT_EQ(inf_bucket,
            sample_value(m, R"(scp_estimator_loop_lateness_seconds_count{actuator="bench-a"})"));
  EXPECT_GT(inf_bucket, 1000.0) << m;
  EXPECT_GT(sample_value(m, R"(scp_estimator_driver_reads_total{actuator="bench-a"})"), 1000.0);

  // The textfile: written, rewritten every interval_s, clean, no temporary left behind.
  const std::string prom = textfiles + "/bench-a.prom";
  ASSERT_TRUE(
      daemon.wait_status([&](const json&) { return std::filesystem::exists(prom); }, Seconds(5)));
  const double first = sample_value(
      read_text(prom), R"(scp_estimator_snapshot_timestamp_seconds{actuator="bench-a"})");
  sleep_s(2.5);
  const std::string text = read_text(prom);
  const double second =
      sample_value(text, R"(scp_estimator_snapshot_timestamp_seconds{actuator="bench-a"})");
  EXPECT_GT(second, first + 0.5) << "not rewritten every interval_s";
  const ProcessResult file_checked = promtool_check(promtool_, prom);
  EXPECT_EQ(file_checked.exit_code, 0) << file_checked.out << file_checked.err << "\n" << text;
  for (const auto& entry : std::filesystem::directory_iterator(textfiles))
    EXPECT_EQ(entry.path().filename().string(), "bench-a.prom") << "left behind: " << entry.path();
}

// A textfile directory the daemon cannot write: one warning, the loop and the socket unharmed.
TEST_F(Metrics, UnwritableDirectoryIsAWarningNotAFault) {
  TempDir dir;
  DaemonProcess daemon(
      dir, {{"metrics", {{"textfile_directory", dir.file("missing")}, {"interval_s", 1.0}}}});
  daemon.start();
  sleep_s(2.5);
  const json st = daemon.status();
  EXPECT_EQ(st.value("state", ""), "running") << st.dump();
  const std::string log = daemon.stderr_text();
  const std::regex warning(R"(warning: metrics: cannot write metrics to .*missing.*)");
  std::size_t count = 0;
  for (std::sregex_iterator it(log.begin(), log.end(), warning), end; it != end; ++it) ++count;
  EXPECT_EQ(count, 1u) << "one warning until it works again:\n" << log;
}

}  // namespace
}  // namespace scp::test

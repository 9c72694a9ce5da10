// Issue 11: the command-line conventions of every program, on the real binaries. Each defect the
// issue lists has its case here: no --version (exit 109), "stauts" answered "A subcommand is
// required" (106), `get --json` rejected, usage errors 105-109, no way to wait for health, batch
// output that jq cannot read, and RUNNING in batch but running on the wire.

#include <chrono>
#include <cstdio>
#include <sstream>

#include "tests/e2e/e2e_util.hpp"

namespace scp::test {
namespace {

constexpr int kExitUsage = 64;

std::vector<std::string> programs() {
  return {estimatord_path(), estimatorctl_path(), SCP_SIMDAQ_PATH};
}

std::string base_name(const std::string& path) {
  return path.substr(path.rfind('/') + 1);
}

// scp-estimatorctl on the daemon's socket, with room for a `wait` longer than run_ctl's 20 s.
ProcessResult ctl(const DaemonProcess& daemon, std::vector<std::string> args, Seconds limit) {
  args.insert(args.begin(), {estimatorctl_path(), "--socket", daemon.socket_path()});
  return run_process(args, limit);
}

TEST(Cli, EveryProgramHasVersion) {
  for (const auto& program : programs()) {
    const ProcessResult r = run_process({program, "--version"}, Seconds(20));
    EXPECT_EQ(r.exit_code, 0) << program << r.err;
    EXPECT_EQ(r.out, base_name(program) + " " + SCP_PROJECT_VERSION + "\n") << program;
  }
}

TEST(Cli, UsageErrorsExit64WithAHint) {
  struct Case {
    std::vector<std::string> argv;
    std::vector<std::string> must_mention;
  };
  const std::vector<Case> cases = {
      {{estimatorctl_path(), "stauts"}, {"unknown command 'stauts'", "did you mean 'status'"}},
      {{estimatorctl_path(), "frobnicate"}, {"unknown command 'frobnicate'", "commands: status"}},
      {{estimatorctl_path()}, {"a command is required"}},
      {{estimatorctl_path(), "--jsno", "get"}, {"--jsno", "did you mean '--json'"}},
      {{estimatorctl_path(), "watch", "--rate", "0"}, {"--rate"}},
      {{estimatorctl_path(), "excitation", "maybe"}, {"maybe"}},
      {{estimatorctl_path(), "wait"}, {"--state"}},
      {{estimatord_path(), "--bogus"}, {"--bogus"}},
      {{estimatord_path(), "--duration", "5"}, {"--offline"}},
      {{SCP_SIMDAQ_PATH}, {"--config"}},
  };
  for (const auto& c : cases) {
    const ProcessResult r = run_process(c.argv, Seconds(20));
    std::string line;
    for (const auto& a : c.argv) line += base_name(a) + " ";
    EXPECT_EQ(r.exit_code, kExitUsage) << line << "\n" << r.err;
    for (const auto& part : c.must_mention)
      EXPECT_TRUE(contains(r.err, part)) << line << ": '" << part << "' missing in:\n" << r.err;
    EXPECT_TRUE(contains(r.err, "--help")) << line << ": no pointer to --help:\n" << r.err;
  }
}

TEST(Cli, HelpDocumentsEveryExitCode) {
  const ProcessResult ctl = run_process({estimatorctl_path(), "--help"}, Seconds(20));
  EXPECT_EQ(ctl.exit_code, 0);
  for (const char* part : {"Exit status", "  0 ", "  1 ", "  2 ", "  3 ", "  64 ", "wait"})
    EXPECT_TRUE(contains(ctl.out, part)) << part << " missing in:\n" << ctl.out;
  const ProcessResult daemon = run_process({estimatord_path(), "--help"}, Seconds(20));
  EXPECT_EQ(daemon.exit_code, 0);
  for (const char* part : {"  64 ", "  78 ", "scp-estimatord(8)"})
    EXPECT_TRUE(contains(daemon.out, part)) << part << " missing in:\n" << daemon.out;
}

TEST(Cli, OptionsAfterTheSubcommand) {
  TempDir dir;
  DaemonProcess daemon(dir);
  daemon.start();
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"get", "--json"}, {"--json", "get"}, {"status", "--json"}}) {
    const ProcessResult r = daemon.run_ctl(args);
    ASSERT_EQ(r.exit_code, 0) << args[0] << " " << args[1] << ": " << r.err;
    const json reply = json::parse(r.out);  // pure JSON, one object
    EXPECT_TRUE(reply["class"] == "ESTIMATE" || reply["class"] == "STATUS") << r.out;
  }
}

TEST(Cli, WaitRunningAndConverged) {
  TempDir dir;
  // A generous convergence threshold so that "converged" is reached within seconds; the wait
  // logic is what is tested, not the estimator.
  DaemonProcess daemon(dir, {{"estimator", {{"converged_rel_sigma", 10.0}}}});
  daemon.start();
  const ProcessResult running =
      ctl(daemon, {"wait", "--state", "running", "--timeout", "30"}, Seconds(60));
  EXPECT_EQ(running.exit_code, 0) << running.err;
  EXPECT_EQ(running.out, "running\n");
  const auto start = std::chrono::steady_clock::now();
  const ProcessResult converged =
      ctl(daemon, {"wait", "--state", "converged", "--timeout", "90", "--json"}, Seconds(120));
  std::printf("[measured] wait --state converged returned after %.1f s\n",
              Seconds(std::chrono::steady_clock::now() - start).count());
  ASSERT_EQ(converged.exit_code, 0) << converged.err;
  const json estimate = json::parse(converged.out);
  EXPECT_EQ(estimate["converged"]["mechanical"], true) << converged.out;
  EXPECT_EQ(estimate["converged"]["thermal"], true) << converged.out;
}

TEST(Cli, WaitTimesOutWithExit3AndTheState) {
  TempDir dir;
  // The simulated sensor reads 400 °C from 0.2 s on: FAULT for ever.
  DaemonProcess daemon(
      dir, {{"driver",
             {{"sim",
               {{"fault",
                 {{"kind", "temperature_out_of_range"}, {"start_s", 0.2}, {"duration_s", 0}}}}}}}});
  daemon.start();
  ASSERT_TRUE(daemon.wait_status([](const json& s) { return s["state"] == "fault"; }, Seconds(20)));
  const ProcessResult r = daemon.run_ctl({"wait", "--state", "running", "--timeout", "1"});
  EXPECT_EQ(r.exit_code, 3) << r.out << r.err;
  EXPECT_TRUE(contains(r.err, "not running after 1 s")) << r.err;
  EXPECT_TRUE(contains(r.err, "fault")) << r.err;
  // Not converged either (the default threshold, 1 s of data at most).
  const ProcessResult c = daemon.run_ctl({"wait", "--state", "converged", "--timeout", "0.5"});
  EXPECT_EQ(c.exit_code, 3) << c.err;
}

TEST(Cli, WaitWithoutDaemonIsUnreachable) {
  TempDir dir;
  const ProcessResult r = run_process(
      {estimatorctl_path(), "--socket", dir.file("none.sock"), "wait", "--state", "running"},
      Seconds(20));
  EXPECT_EQ(r.exit_code, 2) << r.err;
}

TEST(Cli, BatchJsonIsPureJsonLinesWithTheWireStateSpelling) {
  TempDir dir;
  json config = base_config(dir.path());
  write_config(dir.file("c.yaml"), config);
  const ProcessResult r =
      run_process({estimatord_path(), "--config", dir.file("c.yaml"), "--offline", "--duration",
                   "2", "--json", "--record", dir.file("run.csv")},
                  Seconds(120));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::istringstream lines(r.out);
  std::string line;
  int count = 0;
  json summary;
  while (std::getline(lines, line)) {
    ++count;
    summary = json::parse(line);  // throws (fails the test) on a table line
  }
  EXPECT_EQ(count, 1) << r.out;
  EXPECT_EQ(summary["state"], "running");  // as STATUS spells it, not RUNNING
  const std::string csv = read_text(dir.file("run.csv"));
  EXPECT_TRUE(contains(csv, ",running,")) << csv.substr(0, 400);  // the state column
  EXPECT_FALSE(contains(csv, "RUNNING"));
  // Without --json the table comes first and the JSON line is still last.
  const ProcessResult table = run_process(
      {estimatord_path(), "--config", dir.file("c.yaml"), "--offline", "--duration", "1"},
      Seconds(120));
  ASSERT_EQ(table.exit_code, 0) << table.err;
  EXPECT_TRUE(contains(table.out, "state running")) << table.out;
}

}  // namespace
}  // namespace scp::test

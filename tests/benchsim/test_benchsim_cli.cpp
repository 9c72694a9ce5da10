// The scp-benchsim program: its help, a file the replay reader takes, its errors.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <string>

#include "drivers/replay/csv_trace.hpp"
#include "tests/support/run_command.hpp"

namespace {

std::string run(const std::string& args, int& status) {
  return scp::test::run_command(std::string(SCP_BENCHSIM_BINARY) + " " + args, status);
}

std::string temp_path(const std::string& name) {
  return (std::filesystem::temp_directory_path() /
          ("scp-benchsim-" + std::to_string(::getpid()) + "-" + name))
      .string();
}

TEST(BenchsimCli, HelpNamesEveryDeviation) {
  int status = -1;
  const std::string out = run("--help", status);
  EXPECT_EQ(status, 0);
  for (const char* flag : {"--voltage", "--resistance-tempco", "--stiffness-softening",
                           "--cooling-tempco", "--ambient-offset", "--ambient-drift",
                           "--temperature-lag", "--x-zero", "--noise", "--current", "--seed"}) {
    EXPECT_NE(out.find(flag), std::string::npos) << flag;
  }
}

TEST(BenchsimCli, WritesAFileTheReplayReaderTakes) {
  const std::string path = temp_path("light.csv");
  int status = -1;
  const std::string out =
      run("--out " + path + " --config " + SCP_SOURCE_DIR +
              "/config/actuators/light-stiff.yaml --duration 2 --voltage dac-after --noise N1 "
              "--temperature-lag 0.3 --current",
          status);
  ASSERT_EQ(status, 0) << out;
  const auto trace = scp::drivers::replay::load_trace(path);
  EXPECT_EQ(trace.rows.size(), 2001u);
  EXPECT_NEAR(trace.period, 1e-3, 1e-15);
  std::filesystem::remove(path);
}

TEST(BenchsimCli, RefusesABadFlagNamingIt) {
  int status = -1;
  std::string out = run("--out /dev/null --temperature-lag 1e-4", status);
  EXPECT_NE(status, 0);
  EXPECT_NE(out.find("--temperature-lag"), std::string::npos) << out;
  out = run("--out /dev/null --voltage zoh", status);
  EXPECT_NE(status, 0);
  EXPECT_NE(out.find("--voltage"), std::string::npos) << out;
  out = run("--out /nonexistent-dir/x.csv --duration 0.01", status);
  EXPECT_EQ(status, 2);
  EXPECT_NE(out.find("/nonexistent-dir/x.csv"), std::string::npos) << out;
}

}  // namespace

// Runs the built scp-estimatorctl against the real ApiServer in-process.

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <sstream>

#include "daemon/outputs/server/api_server.hpp"
#include "tests/server/server_fixture.hpp"

#ifndef SCP_CTL_PATH
#error "SCP_CTL_PATH must name the scp-estimatorctl binary"
#endif

namespace scp::daemon::server {
namespace {

struct CtlRun {
  int exit_code = -1;
  std::string out;  // stdout and stderr
};

CtlRun run(const std::string& arguments) {
  const std::string command = std::string(SCP_CTL_PATH) + " " + arguments + " 2>&1";
  FILE* pipe = ::popen(command.c_str(), "r");
  CtlRun result;
  if (pipe == nullptr) return result;
  char buffer[4096];
  std::size_t n = 0;
  while ((n = std::fread(buffer, 1, sizeof(buffer), pipe)) > 0) result.out.append(buffer, n);
  const int status = ::pclose(pipe);
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

class CtlTest : public ::testing::Test {
 protected:
  void SetUp() override {
    settings_.socket_path = dir_.path() + "/scp.sock";
    settings_.mode = 0666;
    loop_.base = test::sample_state();
    loop_.start();
    server_ = std::make_unique<ApiServer>(settings_, ServerInfo{"9.9.9-test", "sim", "", ""},
                                          state_, ring_);
    server_->start();
    socket_arg_ = "--socket " + settings_.socket_path;
  }
  void TearDown() override {
    server_->stop();
    loop_.stop();
  }

  test::TempDir dir_;
  ServerSettings settings_;
  rt::Seqlock<PublishedState> state_;
  CommandRing ring_;
  test::FakeLoop loop_{state_, ring_};
  std::unique_ptr<ApiServer> server_;
  std::string socket_arg_;
};

bool contains(const std::string& text, const std::string& fragment) {
  return text.find(fragment) != std::string::npos;
}

TEST_F(CtlTest, GetPrintsTheTable) {
  const CtlRun r = run(socket_arg_ + " get");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  EXPECT_TRUE(contains(r.out, "rel.error")) << r.out;
  // b/m row: θ̂ = 1247·1.01 = 1259.47, θ = 1247, rel.error 1.00e-02.
  std::istringstream lines(r.out);
  std::string line;
  bool found = false;
  while (std::getline(lines, line)) {
    if (line.rfind("b/m ", 0) != 0) continue;
    found = true;
    EXPECT_TRUE(contains(line, "1259.47")) << line;
    EXPECT_TRUE(contains(line, "1247")) << line;
    EXPECT_TRUE(contains(line, "1.00e-02")) << line;
  }
  EXPECT_TRUE(found) << r.out;
  EXPECT_TRUE(contains(r.out, "k/m")) << r.out;
  EXPECT_TRUE(contains(r.out, "b      = 124.7")) << r.out;
  EXPECT_TRUE(contains(r.out, "thermal")) << r.out;
}

// With the refinement on, `get` shows the paper law's and the refined estimate side by side, marks
// the best one and prints the bias flags and the fit's window; `status` its counters.
TEST(CtlRefined, GetPrintsBothEstimatesAndWhichIsBest) {
  test::TempDir dir;
  ServerSettings settings;
  settings.socket_path = dir.path() + "/scp.sock";
  settings.mode = 0666;
  rt::Seqlock<PublishedState> state;
  CommandRing ring;
  test::FakeLoop loop{state, ring};
  loop.base = test::sample_state();
  loop.start();
  rt::Seqlock<refine::RefinedView> refined;
  refine::RefinedView view;
  view.valid = true;
  view.converged = true;
  view.fits = 5;
  view.converged_fits = 5;
  view.windows = 1;
  view.interval_s = 1e6;  // fresh whatever the fake loop's time
  view.theta_hat = {1247.5, 0.8, 1813.0, 0.1, 0.0594059, 1.1001100};
  view.sigma = {2.5, 0.001, 3.0, 1e-4, 1e-8, 1e-7};
  view.t_begin = 0.0;
  view.t_end = 12.0;
  view.samples = 12001;
  view.iterations = 7;
  view.paper_biased = {true, false};
  // Issue 28: only a validated fit is recommended.
  view.validated = true;
  view.validation.mechanical.verdict = scp::refine::Verdict::kAdequate;
  view.validation.thermal.verdict = scp::refine::Verdict::kAdequate;
  refined.store(view);
  ApiServer server(settings, ServerInfo{"9.9.9-test", "sim", "", ""}, state, ring, &refined);
  server.start();
  const CtlRun r = run("--socket " + settings.socket_path + " get");
  server.stop();
  loop.stop();
  ASSERT_EQ(r.exit_code, 0) << r.out;
  EXPECT_TRUE(contains(r.out, "refined*")) << r.out;
  EXPECT_TRUE(contains(r.out, "best: refined; paper law biased: mechanical yes, thermal no"))
      << r.out;
  EXPECT_TRUE(contains(r.out, "refined: window [0.0, 12.0] s (12001 samples)")) << r.out;
  EXPECT_TRUE(contains(r.out, "refined validation: mechanical adequate")) << r.out;
  std::istringstream lines(r.out);
  std::string line;
  bool found = false;
  while (std::getline(lines, line)) {
    if (line.rfind("b/m ", 0) != 0) continue;
    found = true;
    EXPECT_TRUE(contains(line, "1259.47")) << line;   // the paper law's
    EXPECT_TRUE(contains(line, "1247.5")) << line;    // the refined
    EXPECT_TRUE(contains(line, "4.01e-04")) << line;  // its rel. error
  }
  EXPECT_TRUE(found) << r.out;
}

TEST_F(CtlTest, JsonAndEnvironmentSocket) {
  const CtlRun r = run("--json get");  // path from the environment below
  EXPECT_EQ(r.exit_code, 2);           // default path: no daemon there
  const std::string env = "SCP_ESTIMATOR_SOCKET=" + settings_.socket_path + " ";
  const std::string command = env + SCP_CTL_PATH + " --json get";
  FILE* pipe = ::popen(command.c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  char buffer[8192] = {};
  const std::size_t n = std::fread(buffer, 1, sizeof(buffer) - 1, pipe);
  ASSERT_EQ(WEXITSTATUS(::pclose(pipe)), 0);
  const auto j = nlohmann::json::parse(std::string(buffer, n));
  EXPECT_EQ(j["class"], "ESTIMATE");
  EXPECT_DOUBLE_EQ(j["theta_true"][1].get<double>(), 0.8);
}

TEST_F(CtlTest, StatusShowsStateAndLoopStatistics) {
  const CtlRun r = run(socket_arg_ + " status");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  EXPECT_TRUE(contains(r.out, "running")) << r.out;
  EXPECT_TRUE(contains(r.out, "p99 32.0")) << r.out;
  EXPECT_TRUE(contains(r.out, "max 80.5")) << r.out;
  EXPECT_TRUE(contains(r.out, "overruns 3")) << r.out;
}

TEST_F(CtlTest, CommandsAndExitCodes) {
  CtlRun r = run(socket_arg_ + " reset");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_TRUE(contains(r.out, "reset: ok (estimator reset)")) << r.out;
  r = run(socket_arg_ + " excitation off");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_FALSE(state_.load().excitation_enabled);
  r = run(socket_arg_ + " excitation maybe");
  EXPECT_NE(r.exit_code, 0);
  loop_.fault_persists = true;
  r = run(socket_arg_ + " clear-fault");
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "refused (fault persists")) << r.out;
  const auto received = loop_.received();
  ASSERT_EQ(received.size(), 3U);
  EXPECT_EQ(received[1].kind, CommandKind::excitation_off);
}

TEST_F(CtlTest, WatchCountStops) {
  const CtlRun r = run(socket_arg_ + " --json watch --rate 50 --count 3");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  std::istringstream lines(r.out);
  std::string line;
  int estimates = 0;
  while (std::getline(lines, line)) {
    EXPECT_EQ(nlohmann::json::parse(line)["class"], "ESTIMATE");
    ++estimates;
  }
  EXPECT_EQ(estimates, 3);
  const CtlRun human = run(socket_arg_ + " watch --rate 50 --count 2");
  ASSERT_EQ(human.exit_code, 0) << human.out;
  EXPECT_TRUE(contains(human.out, "theta_hat=[1259.47")) << human.out;
}

TEST_F(CtlTest, DaemonNotThere) {
  const CtlRun r = run("--socket " + dir_.path() + "/absent.sock status");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(contains(r.out, "cannot connect to " + dir_.path() + "/absent.sock")) << r.out;
  EXPECT_TRUE(contains(r.out, "No such file")) << r.out;
  EXPECT_TRUE(contains(r.out, "is scp-estimatord running? (systemctl status scp-estimatord)"))
      << r.out;
}

TEST_F(CtlTest, RefusalPrintsTheDaemonsMessage) {
  loop_.paused = true;  // the loop will not answer: the server replies ERROR after 2 s
  const CtlRun r = run(socket_arg_ + " reset");
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_TRUE(contains(r.out, "the loop did not answer 'reset'")) << r.out;
  loop_.paused = false;
  if (::geteuid() == 0 && std::system("command -v setpriv >/dev/null 2>&1") == 0) {
    const std::string command = "setpriv --reuid=65534 --regid=65534 --clear-groups " +
                                std::string(SCP_CTL_PATH) + " " + socket_arg_ + " reset 2>&1";
    FILE* pipe = ::popen(command.c_str(), "r");
    ASSERT_NE(pipe, nullptr);
    char buffer[4096] = {};
    const std::size_t n = std::fread(buffer, 1, sizeof(buffer) - 1, pipe);
    EXPECT_EQ(WEXITSTATUS(::pclose(pipe)), 1);
    EXPECT_TRUE(contains(std::string(buffer, n), "permission denied: 'reset'")) << buffer;
  }
}

}  // namespace
}  // namespace scp::daemon::server

#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>

#include "daemon/core/rt/seqlock.hpp"
#include "daemon/service/reload.hpp"

namespace scp::daemon {
namespace {

TEST(Reload, ChangedKeysAreDottedAndCoverAddedAndRemovedKeys) {
  const std::string before =
      "loop: {period_s: 0.001}\nsafety:\n  temperature_max_c: 150\n  voltage_max_v: 3.3\n"
      "estimator: {theta0: [0, 0, 0, 0, 0, 0]}\n";
  const std::string after =
      "loop: {period_s: 0.001}\nsafety:\n  temperature_max_c: 30\n"
      "estimator: {theta0: [0, 0, 1, 0, 0, 0]}\nlog_level: debug\n";
  const std::vector<std::string> expected = {"estimator.theta0", "log_level",
                                             "safety.temperature_max_c", "safety.voltage_max_v"};
  EXPECT_EQ(changed_keys(before, after), expected);
  EXPECT_TRUE(changed_keys(before, before).empty());
  EXPECT_TRUE(reloadable("log_level"));
  EXPECT_TRUE(reloadable("safety.temperature_max_c"));
  EXPECT_FALSE(reloadable("loop.period_s"));
  EXPECT_FALSE(reloadable("estimator.theta0"));
  EXPECT_TRUE(reloadable("excitation.sines"));
  EXPECT_TRUE(reloadable("recording.compress"));
  EXPECT_TRUE(reloadable("metrics.interval_s"));
  EXPECT_FALSE(reloadable("excitationx"));
  EXPECT_FALSE(reloadable("socket.path"));
  EXPECT_FALSE(reloadable("driver.type"));
}

// Reloadable keys are compared with the last applied file, restart-only keys with the start's:
// a second SIGHUP does not re-apply what the first applied, and still names what needs a restart.
TEST(Reload, PlanComparesAppliedKeysWithTheLastReloadAndTheRestWithTheStart) {
  const std::string path = ::testing::TempDir() + "scp_reload_plan.yaml";
  const std::string started = "excitation: {offset_v: 0}\nloop: {period_s: 0.001}\n";
  const std::string first = "excitation: {profile: custom, offset_v: 1}\nloop: {period_s: 0.002}\n";
  { std::ofstream(path) << first; }
  const ReloadPlan plan = plan_reload(path, started, started);
  EXPECT_TRUE(plan.excitation);
  EXPECT_FALSE(plan.recording);
  EXPECT_EQ(plan.restart, std::vector<std::string>{"loop.period_s"});
  EXPECT_EQ(plan.fresh.excitation.settings.offset, 1.0);
  const ReloadPlan again = plan_reload(path, started, plan.text);
  EXPECT_TRUE(again.applied.empty());
  EXPECT_FALSE(again.excitation);
  EXPECT_EQ(again.restart, std::vector<std::string>{"loop.period_s"});
  { std::ofstream(path) << "excitation: {profile: custom, offset_v: 1, prbs: {order: 99}}\n"; }
  EXPECT_THROW(plan_reload(path, started, plan.text), std::exception);
  std::remove(path.c_str());
}

TEST(Reload, TryLoadNeverWaitsAndCopiesOnlyAConsistentValue) {
  rt::Seqlock<config::SafetySettings> cell;
  config::SafetySettings limits;
  limits.temperature_max_c = 42.0;
  cell.store(limits);
  config::SafetySettings out;
  ASSERT_TRUE(cell.try_load(out));
  EXPECT_EQ(out.temperature_max_c, 42.0);
}

}  // namespace
}  // namespace scp::daemon

// The loop's safety behaviour, command handling and real-time discipline, cycle by cycle.

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>

#include "daemon/config/daemon_config.hpp"
#include "daemon/loop.hpp"
#include "daemon/rt/alloc_counter.hpp"
#include "drivers/sim/sim_driver.hpp"
#include "fake_driver.hpp"

namespace scp::daemon {
namespace {

class LoopTest : public ::testing::Test {
 protected:
  LoopTest() : config_(config::load_config_text("{}", "defaults")) {}

  Loop& make_loop(drivers::Driver& driver) {
    loop_ = std::make_unique<Loop>(config_, driver, *published_, *commands_, nullptr, false);
    return *loop_;
  }
  CycleResult step() {
    const drivers::CycleTime now{static_cast<double>(k_++) * 0.001, 0.001};
    return loop_->cycle(now);
  }
  PublishedState state() const { return published_->load(); }
  void command(CommandKind kind) { ASSERT_TRUE(commands_->try_push({++seq_, kind})); }

  config::DaemonConfig config_;
  std::unique_ptr<rt::Seqlock<PublishedState>> published_ =
      std::make_unique<rt::Seqlock<PublishedState>>();
  std::unique_ptr<CommandRing> commands_ = std::make_unique<CommandRing>();
  std::unique_ptr<Loop> loop_;
  std::uint64_t k_ = 0;
  std::uint64_t seq_ = 0;
};

TEST_F(LoopTest, HoldsZeroVoltsUntilFreshReadingsArrive) {
  testing::FakeDriver driver;
  driver.status = drivers::IoStatus::no_data;
  make_loop(driver);
  step();
  EXPECT_EQ(state().state, RunState::starting);
  EXPECT_EQ(driver.last_written, 0.0);
  EXPECT_EQ(driver.writes, 0);  // only safe_state, never a command
  driver.status = drivers::IoStatus::ok;
  // Advance so that the paper's excitation is non-zero at the loop time of the next cycle.
  k_ = 1000;
  step();
  EXPECT_EQ(state().state, RunState::running);
  EXPECT_GT(driver.last_written, 0.0);
  EXPECT_EQ(driver.writes, 1);
}

TEST_F(LoopTest, OverTemperatureDrivesZeroVoltsInTheSameCycleAndLatchesFault) {
  testing::FakeDriver driver;
  make_loop(driver);
  k_ = 1000;
  step();
  ASSERT_GT(driver.last_written, 0.0);
  driver.next.temperature = config_.safety.temperature_max_c + 1.0;
  step();
  EXPECT_EQ(driver.last_written, 0.0);
  const PublishedState s = state();
  EXPECT_EQ(s.state, RunState::fault);
  EXPECT_EQ(s.voltage_command, 0.0);
  EXPECT_NE(std::string(s.fault_reason.data()).find("temperature_max_c"), std::string::npos)
      << s.fault_reason.data();
  // The cause going away does not clear the fault by itself.
  driver.next.temperature = 30.0;
  for (int i = 0; i < 10; ++i) step();
  EXPECT_EQ(state().state, RunState::fault);
  EXPECT_EQ(driver.last_written, 0.0);
}

TEST_F(LoopTest, ClearFaultIsRefusedWhileTheCauseIsPresent) {
  testing::FakeDriver driver;
  make_loop(driver);
  driver.next.temperature = std::nan("");
  step();
  ASSERT_EQ(state().state, RunState::fault);
  command(CommandKind::clear_fault);
  step();
  PublishedState s = state();
  EXPECT_EQ(s.last_ack.seq, seq_);
  EXPECT_FALSE(s.last_ack.ok);
  EXPECT_EQ(s.state, RunState::fault);

  driver.next.temperature = 30.0;
  step();
  command(CommandKind::clear_fault);
  step();
  s = state();
  EXPECT_TRUE(s.last_ack.ok) << s.last_ack.message.data();
  // Cleared into STARTING: 0 V until the next fresh reading, then RUNNING.
  EXPECT_EQ(s.state, RunState::running);
}

TEST_F(LoopTest, DriverErrorAndStaleDataAreFaults) {
  testing::FakeDriver driver;
  make_loop(driver);
  step();
  driver.status = drivers::IoStatus::error;
  step();
  EXPECT_EQ(state().state, RunState::fault);
  EXPECT_STREQ(state().fault_reason.data(), "fake read failure");

  testing::FakeDriver quiet;
  make_loop(quiet);
  step();
  ASSERT_EQ(state().state, RunState::running);
  quiet.status = drivers::IoStatus::no_data;
  const int stale_cycles = static_cast<int>(config_.safety.stale_timeout_s / 0.001);
  for (int i = 0; i < stale_cycles - 1; ++i) step();
  EXPECT_EQ(state().state, RunState::running);
  for (int i = 0; i < 3; ++i) step();
  EXPECT_EQ(state().state, RunState::fault);
  EXPECT_EQ(quiet.last_written, 0.0);
  EXPECT_NE(std::string(state().fault_reason.data()).find("no fresh reading"), std::string::npos);
}

TEST_F(LoopTest, ExcitationOffHoldsZeroAndResetRestartsTheEstimator) {
  drivers::sim::SimDriver driver(config_.driver.sim);
  driver.open();
  make_loop(driver);
  for (int i = 0; i < 2000; ++i) step();
  EXPECT_GT(state().estimate.updates, 1000U);
  command(CommandKind::excitation_off);
  step();
  EXPECT_EQ(state().voltage_command, 0.0);
  EXPECT_FALSE(state().excitation_enabled);
  EXPECT_TRUE(state().last_ack.ok);
  command(CommandKind::reset);
  step();
  EXPECT_EQ(state().last_ack.seq, seq_);
  EXPECT_LT(state().estimate.updates, 2U);
  command(CommandKind::excitation_on);
  step();
  EXPECT_GT(state().voltage_command, 0.0);
}

TEST_F(LoopTest, PublishesTruthAndPhysicalParametersWithTheSimulator) {
  config_.actuator.mass_kg = 0.1;
  config_.actuator.resistance_ohm = 1.0;
  drivers::sim::SimDriver driver(config_.driver.sim);
  make_loop(driver);
  step();
  const EstimateView e = state().estimate;
  EXPECT_TRUE(e.has_truth);
  EXPECT_NEAR(e.theta_true[0], 1247.0, 1e-9);
  EXPECT_NEAR(e.theta_true[5], 1.0 / 0.9090, 1e-12);
  EXPECT_TRUE(e.has_physical);
}

// After construction, the loop's cycle allocates nothing: the loop thread's real-time promise.
TEST_F(LoopTest, CyclesAllocateNothingAfterStartUp) {
  drivers::sim::SimDriver driver(config_.driver.sim);
  driver.open();
  make_loop(driver);
  step();  // first cycle outside the count, like the daemon's start-up
  rt::alloc::arm();
  const rt::alloc::ScopedAllocationCount count;
  for (int i = 0; i < 20000; ++i) {
    if (i == 5000) {
      command(CommandKind::excitation_off);
    }
    if (i == 6000) command(CommandKind::reset);
    step();
  }
  const auto allocations = count.count();
  rt::alloc::disarm();
  EXPECT_EQ(allocations, 0U);
  EXPECT_EQ(state().estimate.updates > 0, true);
}

}  // namespace
}  // namespace scp::daemon

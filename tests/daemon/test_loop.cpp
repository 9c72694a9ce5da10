// The loop's safety behaviour, command handling and real-time discipline, cycle by cycle.

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>

#include "daemon/config/daemon_config.hpp"
#include "daemon/core/loop.hpp"
#include "daemon/core/rt/alloc_counter.hpp"
#include "drivers/sim/sim_driver.hpp"
#include "fake_driver.hpp"

namespace scp::daemon {
namespace {

class LoopTest : public ::testing::Test {
 protected:
  // What an empty configuration file gives (test_config.cpp checks that it is), without linking
  // the YAML loader and the drivers it validates.
  LoopTest() { config::derive_settings(config_); }

  Loop& make_loop(drivers::Driver& driver, HandOffRing* handoff = nullptr) {
    loop_ =
        std::make_unique<Loop>(config_, driver, *published_, *commands_, nullptr, false, handoff);
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

// A device that measures the heater's current: the current reaches the refinement; once
// measured, a NaN current is a sensor fault and one above safety.current_max_a a limit fault.
TEST_F(LoopTest, AMeasuredCurrentIsHandedOffAndCheckedLikeTheOtherSignals) {
  testing::FakeDriver driver;
  driver.next = {0.0, 1e-3, 0.0, 40.0, 1.5};
  driver.next.current = 0.5;
  auto handoff = std::make_unique<HandOffRing>();
  make_loop(driver, handoff.get());
  k_ = 1000;
  step();
  ASSERT_EQ(state().state, RunState::running);
  HandOff h;
  ASSERT_TRUE(handoff->try_pop(h));
  EXPECT_DOUBLE_EQ(h.sample.current, 0.5);

  driver.next.current = std::nan("");
  step();
  PublishedState s = state();
  EXPECT_EQ(s.state, RunState::fault);
  EXPECT_EQ(driver.last_written, 0.0);
  EXPECT_NE(std::string(s.fault_reason.data()).find("heater current is not a finite number"),
            std::string::npos)
      << s.fault_reason.data();

  driver.next.current = config_.safety.current_max_a * 2.0;
  step();
  command(CommandKind::clear_fault);
  step();
  s = state();
  EXPECT_FALSE(s.last_ack.ok);  // the cause is still there: a current above the limit
  EXPECT_NE(std::string(s.last_ack.message.data()).find("safety.current_max_a"), std::string::npos)
      << s.last_ack.message.data();
}

// A device without a current channel (NaN from the first sample) runs as before.
TEST_F(LoopTest, ACurrentNeverMeasuredIsNotRequired) {
  testing::FakeDriver driver;
  make_loop(driver);
  k_ = 1000;
  for (int i = 0; i < 5; ++i) step();
  EXPECT_EQ(state().state, RunState::running);
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

// A device absent or slow at start (issue 9) is awaited in STARTING at 0 V, with the driver's
// reason published, however long it takes (driver.start_timeout_s is the service's bound); it is
// not a fault. Once it has delivered a reading, the same error is a fault.
TEST_F(LoopTest, ADeviceSilentSinceStartIsAwaitedNotFaulted) {
  testing::FakeDriver driver;
  driver.status = drivers::IoStatus::error;
  make_loop(driver);
  const int stale_cycles = static_cast<int>(config_.safety.stale_timeout_s / 0.001);
  for (int i = 0; i < 10 * stale_cycles; ++i) step();
  PublishedState s = state();
  EXPECT_EQ(s.state, RunState::starting);
  EXPECT_TRUE(s.awaiting_device);
  EXPECT_STREQ(s.waiting_reason.data(), "fake read failure");
  EXPECT_EQ(s.faults.count, 0U);
  EXPECT_EQ(driver.writes, 0);  // only 0 V (safe_state), every cycle
  EXPECT_EQ(driver.last_written, 0.0);
  EXPECT_EQ(driver.safe_states, 10 * stale_cycles);

  driver.status = drivers::IoStatus::no_data;  // connected, nothing sent yet
  for (int i = 0; i < 3 * stale_cycles; ++i) step();
  s = state();
  EXPECT_EQ(s.state, RunState::starting);
  EXPECT_STREQ(s.waiting_reason.data(), "the device sends no data yet");

  driver.status = drivers::IoStatus::ok;
  k_ = 1000;
  step();
  s = state();
  EXPECT_EQ(s.state, RunState::running);
  EXPECT_FALSE(s.awaiting_device);
  EXPECT_STREQ(s.waiting_reason.data(), "");

  driver.status = drivers::IoStatus::error;
  step();
  s = state();
  EXPECT_EQ(s.state, RunState::fault);
  EXPECT_FALSE(s.awaiting_device);
  EXPECT_EQ(s.faults.count, 1U);
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

// The same with the refinement's hand-off ring attached, filling up and then full (every push
// fails and is counted).
TEST_F(LoopTest, HandingSamplesOffAllocatesNothing) {
  drivers::sim::SimDriver driver(config_.driver.sim);
  driver.open();
  auto handoff = std::make_unique<HandOffRing>();
  make_loop(driver, handoff.get());
  step();
  // All but 1000 slots taken, so that both the successful and the failing push are counted.
  for (std::size_t i = 0; i < kHandOffCapacity - 1000; ++i) handoff->try_push({});
  rt::alloc::arm();
  const rt::alloc::ScopedAllocationCount count;
  for (int i = 0; i < 3000; ++i) step();
  const auto allocations = count.count();
  rt::alloc::disarm();
  EXPECT_EQ(allocations, 0U);
  EXPECT_GT(loop_->dropped_handoff_samples(), 0U);
}

// A reload's excitation reaches the loop over the exchange's rings: it takes effect in the next
// cycle, the old one is given back to be freed off the loop, and the loop allocates nothing.
TEST_F(LoopTest, ExcitationHandOverTakesEffectNextCycleAndAllocatesNothing) {
  drivers::sim::SimDriver driver(config_.driver.sim);
  driver.open();
  auto exchange = std::make_unique<ExcitationExchange>();
  make_loop(driver);
  loop_->follow_excitation(exchange.get());
  for (int i = 0; i < 100; ++i) step();
  ASSERT_EQ(state().state, RunState::running);
  EXPECT_NE(state().voltage_command, 1.25);
  excitation::ExcitationSettings constant;
  constant.offset = 1.25;
  for (int round = 0; round < 3; ++round) {
    constant.offset = 1.25 + 0.25 * round;
    ASSERT_TRUE(exchange->offer(std::make_unique<excitation::Excitation>(constant), -1));
    rt::alloc::arm();
    const rt::alloc::ScopedAllocationCount count;
    step();
    const auto allocations = count.count();
    rt::alloc::disarm();
    EXPECT_EQ(allocations, 0U);
    EXPECT_EQ(state().voltage_command, constant.offset);
  }
  // excitation.enabled alone: no new excitation, the flag only.
  ASSERT_TRUE(exchange->offer(nullptr, 0));
  step();
  EXPECT_EQ(state().voltage_command, 0.0);
  EXPECT_FALSE(state().excitation_enabled);
  ASSERT_TRUE(exchange->offer(nullptr, 1));
  step();
  EXPECT_EQ(state().voltage_command, 1.75);
}

// The ring the loop records to is read each cycle: null stops the rows, a ring starts them.
TEST_F(LoopTest, RecordingFollowsTheRingPointer) {
  drivers::sim::SimDriver driver(config_.driver.sim);
  driver.open();
  auto ring = std::make_unique<RecordRing>();
  std::atomic<RecordRing*> live{nullptr};
  make_loop(driver);
  loop_->follow_recording(&live);
  for (int i = 0; i < 100; ++i) step();
  EXPECT_EQ(ring->size_approx(), 0U);
  EXPECT_FALSE(state().recording);
  live.store(ring.get());
  for (int i = 0; i < 100; ++i) step();
  EXPECT_EQ(ring->size_approx(), 100U);
  EXPECT_TRUE(state().recording);
  live.store(nullptr);
  for (int i = 0; i < 100; ++i) step();
  EXPECT_EQ(ring->size_approx(), 100U);
}

TEST_F(LoopTest, HandsOffEverySampleFedToTheEstimatorWithTBarAndVoltage) {
  testing::FakeDriver driver;
  driver.next = {0.0, 1e-3, 0.0, 40.0, 1.5};
  auto handoff = std::make_unique<HandOffRing>();
  make_loop(driver, handoff.get());
  k_ = 1000;
  for (int i = 0; i < 5; ++i) step();
  // ẋ is measured here (finite), so every fresh sample is fed as it is.
  EXPECT_EQ(handoff->size_approx(), 5U);
  HandOff h;
  ASSERT_TRUE(handoff->try_pop(h));
  EXPECT_DOUBLE_EQ(h.sample.t, 1.0);
  EXPECT_DOUBLE_EQ(h.sample.x, 1e-3);
  EXPECT_DOUBLE_EQ(h.sample.tbar, 40.0 - config_.actuator.ambient_c);
  EXPECT_DOUBLE_EQ(h.sample.voltage, 1.5);
  EXPECT_TRUE(std::isinf(h.sample.voltage_since) && h.sample.voltage_since < 0);
  EXPECT_EQ(state().handoff_dropped, 0U);
}

TEST_F(LoopTest, AFullHandOffRingCountsDropsAndTheNextSampleStartsANewSegment) {
  testing::FakeDriver driver;
  auto handoff = std::make_unique<HandOffRing>();
  make_loop(driver, handoff.get());
  k_ = 1000;
  for (std::size_t i = 0; i < kHandOffCapacity + 3; ++i) step();
  EXPECT_EQ(loop_->dropped_handoff_samples(), 3U);
  EXPECT_EQ(state().handoff_dropped, 3U);
  HandOff h;
  ASSERT_TRUE(handoff->try_pop(h));
  const std::uint64_t first = h.segment;
  while (handoff->try_pop(h)) EXPECT_EQ(h.segment, first);
  step();
  ASSERT_TRUE(handoff->try_pop(h));
  EXPECT_NE(h.segment, first);
}

TEST_F(LoopTest, AResetAndAFaultEachStartANewSegment) {
  testing::FakeDriver driver;
  auto handoff = std::make_unique<HandOffRing>();
  make_loop(driver, handoff.get());
  k_ = 1000;
  HandOff h;
  step();
  ASSERT_TRUE(handoff->try_pop(h));
  const std::uint64_t before_reset = h.segment;
  command(CommandKind::reset);
  step();
  ASSERT_TRUE(handoff->try_pop(h));
  const std::uint64_t after_reset = h.segment;
  EXPECT_NE(after_reset, before_reset);
  // A read failure faults the loop; it recovers after safety.recover_after_s of healthy readings.
  driver.status = drivers::IoStatus::error;
  step();
  driver.status = drivers::IoStatus::ok;
  while (state().state != RunState::running && k_ < 10000) step();
  ASSERT_EQ(state().state, RunState::running);
  step();
  while (handoff->try_pop(h)) {
  }
  EXPECT_NE(h.segment, after_reset);
}

}  // namespace
}  // namespace scp::daemon

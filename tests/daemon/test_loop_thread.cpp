// The loop thread with the loop core alone: cycles to absolute deadlines until stopped, its
// statistics published with the snapshots, 0 V as its last act; a real-time set-up that must not
// fail is reported, and the loop never runs.

#include <gtest/gtest.h>

#include <chrono>
#include <memory>
#include <string>
#include <thread>

#include "daemon/config/daemon_config.hpp"
#include "daemon/core/loop.hpp"
#include "daemon/core/loop_thread.hpp"
#include "fake_driver.hpp"

namespace scp::daemon {
namespace {

class LoopThreadTest : public ::testing::Test {
 protected:
  LoopThreadTest() {
    config::derive_settings(config_);
    config_.loop.realtime = rt::RtSettings{};
    config_.loop.realtime.priority = 0;  // ordinary scheduling: no privilege needed
    config_.loop.realtime.lock_memory = false;
    config_.loop.realtime.prefault_heap_bytes = 0;
    config_.loop.realtime.prefault_stack_bytes = 0;
  }

  config::DaemonConfig config_;
  testing::FakeDriver driver_;
  std::unique_ptr<rt::Seqlock<PublishedState>> published_ =
      std::make_unique<rt::Seqlock<PublishedState>>();
  std::unique_ptr<CommandRing> commands_ = std::make_unique<CommandRing>();
  std::unique_ptr<rt::LatencyHistogram> lateness_ = std::make_unique<rt::LatencyHistogram>();
  rt::ServiceNotifier notifier_;  // outside systemd: every notification is a no-op
};

TEST_F(LoopThreadTest, RunsCyclesUntilStoppedAndLeavesZeroVolts) {
  Loop loop(config_, driver_, *published_, *commands_, nullptr, false);
  LoopThread thread(loop, config_.loop, notifier_, *lateness_);
  ASSERT_TRUE(thread.start()) << thread.setup_error();
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (published_->load().loop.cycles < 200 && std::chrono::steady_clock::now() < give_up) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  thread.stop();
  const PublishedState last = published_->load();
  EXPECT_GE(last.loop.cycles, 200U);
  EXPECT_GE(last.uptime_s, 0.199);  // loop time is the deadline's: one period per cycle
  EXPECT_EQ(loop.state(), RunState::stopping);
  EXPECT_GT(driver_.writes, 0);  // it ran, excitation on
  EXPECT_EQ(driver_.last_written, 0.0);
  thread.stop();  // idempotent
}

TEST_F(LoopThreadTest, ARequiredRealTimeSettingThatCannotWorkStopsTheStart) {
  config_.loop.realtime.priority = 100;  // beyond SCHED_FIFO's 1..99
  config_.loop.realtime.required = true;
  Loop loop(config_, driver_, *published_, *commands_, nullptr, false);
  LoopThread thread(loop, config_.loop, notifier_, *lateness_);
  EXPECT_FALSE(thread.start());
  EXPECT_NE(thread.setup_error().find("priority"), std::string::npos) << thread.setup_error();
  EXPECT_EQ(driver_.writes, 0);
  EXPECT_EQ(published_->load().loop.cycles, 0U);
}

}  // namespace
}  // namespace scp::daemon

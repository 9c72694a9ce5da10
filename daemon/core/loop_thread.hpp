#pragma once
// The loop's timing: the thread that puts itself into real-time shape, then runs Loop::cycle at
// absolute deadlines (cyclictest's timerthread, ros2_control's sleep_for_periodic_cycle), keeps
// the lateness and execution statistics, and pets the systemd watchdog only after cycles that
// completed. Everything is built before the thread starts, so that it allocates nothing after
// its real-time set-up.

#include <atomic>
#include <string>
#include <thread>
#include <vector>

#include "daemon/config/daemon_config.hpp"
#include "daemon/core/loop.hpp"
#include "daemon/core/rt/latency_histogram.hpp"
#include "daemon/core/rt/sd_notify.hpp"

namespace scp::daemon {

class LoopThread {
 public:
  // Everything referenced must outlive the thread. `lateness` is the fine histogram the server
  // reads for STATUS.
  LoopThread(Loop& loop, const config::LoopSettings& settings, rt::ServiceNotifier& notifier,
             rt::LatencyHistogram& lateness) noexcept;
  ~LoopThread();  // stop()
  LoopThread(const LoopThread&) = delete;
  LoopThread& operator=(const LoopThread&) = delete;

  // Starts the thread (on the loop's larger stack) and waits until its real-time set-up is done.
  // False when loop.realtime.required and a setting could not be applied: the thread has ended,
  // setup_error() says why.
  bool start();
  // The real-time settings that did not take effect (valid after start()).
  const std::vector<std::string>& warnings() const noexcept { return warnings_; }
  const std::string& setup_error() const noexcept { return setup_error_; }
  // Idempotent; returns once the loop has shut down (its last act is 0 V, Loop::shutdown).
  void stop() noexcept;

 private:
  void run() noexcept;

  Loop& loop_;
  const config::LoopSettings& settings_;
  rt::ServiceNotifier& notifier_;
  rt::LatencyHistogram& lateness_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> started_{false};
  std::atomic<bool> setup_failed_{false};
  std::vector<std::string> warnings_;  // written before started_, read after
  std::string setup_error_;
  std::thread thread_;
};

}  // namespace scp::daemon

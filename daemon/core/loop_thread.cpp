#include "daemon/core/loop_thread.hpp"

#include <chrono>
#include <cmath>
#include <exception>

#include "daemon/core/rt/alloc_hook.hpp"
#include "daemon/core/rt/loop_stats.hpp"
#include "daemon/core/rt/periodic_timer.hpp"
#include "daemon/core/rt/rt_setup.hpp"

namespace scp::daemon {

LoopThread::LoopThread(Loop& loop, const config::LoopSettings& settings,
                       rt::ServiceNotifier& notifier, rt::LatencyHistogram& lateness) noexcept
    : loop_(loop), settings_(settings), notifier_(notifier), lateness_(lateness) {}

LoopThread::~LoopThread() {
  stop();
}

bool LoopThread::start() {
  // The loop's larger stack, then the small default again for the threads started later.
  const bool loop_stack_set = rt::set_default_thread_stack(rt::kLoopThreadStackBytes);
  thread_ = std::thread([this] { run(); });
  if (loop_stack_set) rt::set_default_thread_stack(rt::kThreadStackBytes);
  while (!started_.load(std::memory_order_acquire) &&
         !setup_failed_.load(std::memory_order_acquire)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  if (!setup_failed_.load(std::memory_order_acquire)) return true;
  thread_.join();
  return false;
}

void LoopThread::stop() noexcept {
  stop_.store(true, std::memory_order_release);
  if (thread_.joinable()) thread_.join();
}

void LoopThread::run() noexcept {
  const double period_s = settings_.period_s;
  const auto period =
      std::chrono::nanoseconds(static_cast<std::int64_t>(std::llround(period_s * 1e9)));
  try {
    warnings_ = rt::apply_rt_settings(settings_.realtime);
  } catch (const std::exception& e) {
    setup_error_ = e.what();
    setup_failed_.store(true, std::memory_order_release);
    return;
  }
  // period_s is validated to [1e-4, 1] s by the config, so the timer cannot refuse it.
  rt::PeriodicTimer timer(period);
  rt::LoopStatsAccumulator stats;
  stats.attach(&lateness_);
  rt::WatchdogPacer pacer(notifier_.watchdog_interval(), period);
  // From here on the thread must not allocate; the benchmark build counts it (alloc_hook.hpp).
  const std::int64_t allocations_at_start = rt::thread_allocation_count();
  timer.start();
  started_.store(true, std::memory_order_release);
  while (!stop_.load(std::memory_order_acquire)) {
    const rt::WakeResult wake = timer.wait_next();
    stats.record_wake(wake);
    LoopStatistics loop_stats = stats.snapshot();
    if (allocations_at_start >= 0) {
      loop_stats.allocations_counted = true;
      loop_stats.allocations =
          static_cast<std::uint64_t>(rt::thread_allocation_count() - allocations_at_start);
    }
    loop_.set_loop_statistics(loop_stats);
    // The deadline's CLOCK_MONOTONIC time lets a driver stamp samples when they were taken.
    const drivers::CycleTime now{static_cast<double>(wake.cycle) * period_s, period_s,
                                 wake.deadline_ns};
    loop_.cycle(now);
    stats.record_exec(timer.mark_cycle_end());
    // Only a loop that completes its cycles pets the watchdog: a stalled driver call or a
    // wedged loop stops the pings and systemd restarts the service.
    if (pacer.due(wake.cycle)) notifier_.watchdog();
  }
  loop_.shutdown();
}

}  // namespace scp::daemon

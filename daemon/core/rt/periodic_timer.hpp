#pragma once
// Absolute-deadline periodic wake-ups for the real-time loop, after cyclictest's timerthread and
// ros2_control's sleep_for_periodic_cycle: sleeping to an absolute CLOCK_MONOTONIC deadline does
// not accumulate drift the way a relative sleep does, and the loop's time is t = k · period on the
// deadline grid, whatever the wake-up jitter.

#include <chrono>
#include <cstdint>

namespace scp::rt {

// What one wake-up looked like.
struct WakeResult {
  std::int64_t deadline_ns = 0;  // CLOCK_MONOTONIC, absolute: the deadline this cycle serves
  std::uint64_t cycle = 0;       // k: counts skipped periods too, so the loop time is k · period
  std::int64_t lateness_ns = 0;  // wake-up time − deadline (≥ 0 in practice)
  std::uint64_t missed = 0;      // whole periods skipped just before this cycle
  bool overrun = false;          // the previous cycle's work ran past this cycle's deadline
};

// Execution time of one cycle, from the wake-up to mark_cycle_end().
struct CycleEnd {
  std::int64_t exec_ns = 0;
  bool overran = false;  // the work ended after the next deadline
};

class PeriodicTimer {
 public:
  // Throws std::invalid_argument when period ≤ 0.
  explicit PeriodicTimer(std::chrono::nanoseconds period);

  // Takes "now" as the first deadline: the first wait_next() returns at once with cycle 0.
  void start() noexcept;
  // Same, with an explicit first deadline (for tests and for aligning several loops).
  void start_at(std::int64_t first_deadline_ns) noexcept;

  // Sleeps until the next deadline and reports the wake-up. When the previous cycle overran so far
  // that whole periods have already passed, those periods are skipped (counted in `missed`, and in
  // `cycle`) and the latest deadline not in the future is served at once: a stall costs data, never
  // a burst of back-to-back cycles that would feed the estimator stale timing.
  WakeResult wait_next() noexcept;

  // Call when the cycle's work is done: measures execution time since the last wake-up.
  CycleEnd mark_cycle_end() noexcept;

  std::int64_t period_ns() const noexcept { return period_ns_; }
  bool started() const noexcept { return started_; }

 private:
  std::int64_t period_ns_;
  std::int64_t next_deadline_ns_ = 0;  // the deadline the next wait_next() serves (before skipping)
  std::uint64_t next_cycle_ = 0;
  std::int64_t last_deadline_ns_ = 0;
  std::int64_t last_wake_ns_ = 0;
  bool started_ = false;
};

}  // namespace scp::rt

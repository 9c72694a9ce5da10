#include "daemon/core/rt/periodic_timer.hpp"

#include <cerrno>
#include <ctime>
#include <stdexcept>
#include <string>

#include "common/clock.hpp"

namespace scp::rt {

using clock::monotonic_ns;
using clock::to_timespec;

PeriodicTimer::PeriodicTimer(std::chrono::nanoseconds period) : period_ns_(period.count()) {
  if (period_ns_ <= 0) {
    throw std::invalid_argument("PeriodicTimer: the period must be positive (got " +
                                std::to_string(period_ns_) + " ns)");
  }
}

void PeriodicTimer::start() noexcept {
  start_at(monotonic_ns());
}

void PeriodicTimer::start_at(std::int64_t first_deadline_ns) noexcept {
  next_deadline_ns_ = first_deadline_ns;
  next_cycle_ = 0;
  last_deadline_ns_ = first_deadline_ns;
  last_wake_ns_ = first_deadline_ns;
  started_ = true;
}

WakeResult PeriodicTimer::wait_next() noexcept {
  if (!started_) start();
  WakeResult r;
  std::int64_t now = monotonic_ns();
  if (now > next_deadline_ns_ && next_cycle_ > 0) {
    r.overrun = true;
    // Whole periods already gone: skip them, serve the latest deadline that is not in the future.
    const std::uint64_t skip = static_cast<std::uint64_t>((now - next_deadline_ns_) / period_ns_);
    next_deadline_ns_ += static_cast<std::int64_t>(skip) * period_ns_;
    next_cycle_ += skip;
    r.missed = skip;
  } else {
    const timespec deadline = to_timespec(next_deadline_ns_);
    // TIMER_ABSTIME: an interrupted sleep is simply resumed to the same deadline.
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &deadline, nullptr) == EINTR) {
    }
    now = monotonic_ns();
  }
  r.deadline_ns = next_deadline_ns_;
  r.cycle = next_cycle_;
  r.lateness_ns = now - next_deadline_ns_;
  last_deadline_ns_ = next_deadline_ns_;
  last_wake_ns_ = now;
  next_deadline_ns_ += period_ns_;
  ++next_cycle_;
  return r;
}

CycleEnd PeriodicTimer::mark_cycle_end() noexcept {
  const std::int64_t now = monotonic_ns();
  CycleEnd e;
  e.exec_ns = now - last_wake_ns_;
  e.overran = now > last_deadline_ns_ + period_ns_;
  return e;
}

}  // namespace scp::rt

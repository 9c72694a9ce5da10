#include <gtest/gtest.h>
#include <pthread.h>

#include <atomic>
#include <csignal>
#include <ctime>
#include <thread>

#include "common/clock.hpp"
#include "daemon/core/rt/alloc_counter.hpp"
#include "daemon/core/rt/periodic_timer.hpp"

namespace scp::rt {
namespace {

using namespace std::chrono_literals;

void sleep_ns(std::int64_t ns) {
  timespec ts{static_cast<time_t>(ns / 1'000'000'000), static_cast<long>(ns % 1'000'000'000)};
  while (nanosleep(&ts, &ts) != 0) {
  }
}

TEST(PeriodicTimer, RejectsNonPositivePeriod) {
  EXPECT_THROW(PeriodicTimer(0ns), std::invalid_argument);
  EXPECT_THROW(PeriodicTimer(-1ms), std::invalid_argument);
}

TEST(PeriodicTimer, WakesOnTheAbsoluteGrid) {
  constexpr std::int64_t kPeriod = 1'000'000;  // 1 ms
  PeriodicTimer timer{std::chrono::nanoseconds(kPeriod)};
  const std::int64_t t0 = clock::monotonic_ns();
  timer.start_at(t0);
  std::uint64_t missed_total = 0;
  WakeResult last{};
  for (int i = 0; i < 30; ++i) {
    last = timer.wait_next();
    missed_total += last.missed;
    // The grid is exact whatever the jitter: deadline = t0 + k · period.
    ASSERT_EQ(last.deadline_ns, t0 + static_cast<std::int64_t>(last.cycle) * kPeriod);
    ASSERT_GE(last.lateness_ns, 0);
  }
  // Skipped periods are counted in the index, so index = calls − 1 + skipped.
  EXPECT_EQ(last.cycle, 29 + missed_total);
  // It really slept: 29 periods after t0 at least.
  EXPECT_GE(clock::monotonic_ns() - t0, 29 * kPeriod);
}

TEST(PeriodicTimer, SkipsWholeMissedPeriodsWithoutBursting) {
  constexpr std::int64_t kPeriod = 10'000'000;  // 10 ms
  PeriodicTimer timer{std::chrono::nanoseconds(kPeriod)};
  const std::int64_t t0 = clock::monotonic_ns() - kPeriod * 21 / 2;  // 10.5 periods in the past
  timer.start_at(t0);
  const WakeResult first = timer.wait_next();
  EXPECT_EQ(first.cycle, 0U);
  EXPECT_EQ(first.missed, 0U);
  EXPECT_FALSE(first.overrun);
  // Now ≈ t0 + 10.5 periods: the deadlines of cycles 1..9 are gone; cycle 10 (t0 + 10 periods) is
  // the latest one not in the future and is served at once, half a period late.
  const WakeResult second = timer.wait_next();
  EXPECT_TRUE(second.overrun);
  EXPECT_EQ(second.missed, 9U);
  EXPECT_EQ(second.cycle, 10U);
  EXPECT_EQ(second.deadline_ns, t0 + 10 * kPeriod);
  EXPECT_GE(second.lateness_ns, kPeriod / 2);
  EXPECT_LT(second.lateness_ns, kPeriod);
  // Then back on the grid: the next wake-up sleeps to cycle 11 instead of bursting.
  const WakeResult third = timer.wait_next();
  EXPECT_EQ(third.cycle, 11U);
  EXPECT_EQ(third.missed, 0U);
  EXPECT_FALSE(third.overrun);
  EXPECT_GE(clock::monotonic_ns(), t0 + 11 * kPeriod);
}

TEST(PeriodicTimer, MeasuresExecutionTimeAndOverrun) {
  // 50 ms: the 1.5-period sleep below must not stretch past 2 periods on a loaded machine.
  constexpr std::int64_t kPeriod = 50'000'000;
  PeriodicTimer timer{std::chrono::nanoseconds(kPeriod)};
  timer.start();
  timer.wait_next();
  sleep_ns(kPeriod + kPeriod / 2);
  const CycleEnd slow = timer.mark_cycle_end();
  EXPECT_GE(slow.exec_ns, kPeriod + kPeriod / 2);
  EXPECT_TRUE(slow.overran);
  const WakeResult next = timer.wait_next();
  EXPECT_TRUE(next.overrun);
  EXPECT_EQ(next.missed, 0U);  // 1.5 periods: late, but no whole period lost
  const CycleEnd quick = timer.mark_cycle_end();
  EXPECT_GE(quick.exec_ns, 0);
  EXPECT_LT(quick.exec_ns, kPeriod);
}

std::atomic<int> g_signals{0};
void count_signal(int) {
  g_signals.fetch_add(1);
}

TEST(PeriodicTimer, SignalDuringSleepDoesNotWakeEarly) {
  struct sigaction sa {};
  struct sigaction old {};
  sa.sa_handler = count_signal;
  sa.sa_flags = 0;  // no SA_RESTART: clock_nanosleep returns EINTR and must be resumed
  sigemptyset(&sa.sa_mask);
  ASSERT_EQ(sigaction(SIGUSR1, &sa, &old), 0);

  constexpr std::int64_t kPeriod = 60'000'000;  // 60 ms
  PeriodicTimer timer{std::chrono::nanoseconds(kPeriod)};
  timer.start();
  timer.wait_next();
  const pthread_t self = pthread_self();
  std::thread interrupter([self] {
    sleep_ns(15'000'000);
    pthread_kill(self, SIGUSR1);
    sleep_ns(15'000'000);
    pthread_kill(self, SIGUSR1);
  });
  const WakeResult w = timer.wait_next();
  const std::int64_t woke = clock::monotonic_ns();
  interrupter.join();
  sigaction(SIGUSR1, &old, nullptr);
#ifdef __SANITIZE_THREAD__
  // ThreadSanitizer defers handlers and merges a signal that arrives while one is pending, so
  // only "at least one interrupted the sleep" can be checked there.
  EXPECT_GE(g_signals.load(), 1);
#else
  EXPECT_EQ(g_signals.load(), 2);
#endif
  EXPECT_EQ(w.cycle, 1U);
  EXPECT_GE(woke, w.deadline_ns);
  EXPECT_GE(w.lateness_ns, 0);
}

TEST(PeriodicTimer, WaitAndMarkDoNotAllocate) {
  PeriodicTimer timer(std::chrono::nanoseconds(200'000));
  timer.start();
  alloc::arm();
  const alloc::ScopedAllocationCount count;
  for (int i = 0; i < 20; ++i) {
    timer.wait_next();
    timer.mark_cycle_end();
  }
  EXPECT_EQ(count.count(), 0U);
  alloc::disarm();
}

}  // namespace
}  // namespace scp::rt

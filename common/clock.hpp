#pragma once
// The two clocks the project reads, from one place: CLOCK_MONOTONIC for deadlines and intervals,
// CLOCK_REALTIME for time stamps a lab lines up with its other instruments. Both are vDSO reads
// (no system call, no allocation, no lock): safe on the real-time loop.

#include <time.h>

#include <cstdint>

namespace scp::clock {

inline constexpr std::int64_t kNsPerSecond = 1'000'000'000;

inline std::int64_t to_ns(const timespec& ts) noexcept {
  return static_cast<std::int64_t>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

inline timespec to_timespec(std::int64_t ns) noexcept {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(ns / kNsPerSecond);
  ts.tv_nsec = static_cast<long>(ns % kNsPerSecond);
  return ts;
}

inline std::int64_t monotonic_ns() noexcept {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return to_ns(ts);
}

inline double monotonic_s() noexcept {
  return static_cast<double>(monotonic_ns()) * 1e-9;
}

// Nanoseconds since 1970-01-01 UTC.
inline std::int64_t unix_ns() noexcept {
  timespec ts{};
  ::clock_gettime(CLOCK_REALTIME, &ts);
  return to_ns(ts);
}

}  // namespace scp::clock

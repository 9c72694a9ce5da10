#pragma once
// Quality gate for a transaction's time stamp (issue 9, "real link timing").
//
// A transaction's midpoint marks when the device sampled (or applied the command) only if the
// transaction took its usual time. On a loaded machine the loop thread is preempted between its
// clock reading and the request leaving, or the reply waits in the socket until the thread runs
// again (or the device answers late): the transaction stretches by milliseconds and its midpoint
// moves by half the stretch, whereas the device's event stays where it was. Those few stretched
// transactions, not the many ordinary ones, made stamped thermal estimates worse than the loop's
// deadlines under load (docs/driver-modbus.md, "Time", has the measurement).
//
// The gate learns the usual duration as the median of the last kWindow transactions (robust to
// the outliers it is there to catch, and following a line that became slower for good), and the
// usual midpoint relative to the cycle's deadline as the median over the last kWindow accepted
// ones. A transaction longer than usual + tolerance is "stretched": the event is then assumed
// to have kept its usual place relative to the deadline (what the deadline mode assumes for
// every sample, offset included), clamped into what the transaction's own bounds allow: not
// before begin + usual/2 (had the stretch come entirely after the reply) and not after
// end − usual/2 (entirely before the request). Fixed-size, no allocation: the loop thread runs it.

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>

namespace scp::drivers::modbus {

class StampGate {
 public:
  static constexpr std::size_t kWindow = 64;
  // Fewer accepted transactions than this: nothing to compare with, every stamp is taken.
  static constexpr std::size_t kWarmUp = 16;
  // The smallest stretch called one: three times the 0.1 ms scale the stamps are about, and
  // above a loaded machine's ordinary scheduling jitter (docs/driver-modbus.md, "Time"); or 10 %
  // of the usual duration on a slow line.
  static constexpr std::int64_t kMinToleranceNs = 300'000;

  struct Stamp {
    std::int64_t midpoint_ns = 0;
    bool stretched = false;
  };

  // begin_ns/end_ns: the transaction as the line saw it; deadline_ns: the cycle's deadline.
  Stamp judge(std::int64_t begin_ns, std::int64_t end_ns, std::int64_t deadline_ns) noexcept {
    const std::int64_t duration = end_ns - begin_ns;
    const std::int64_t midpoint = begin_ns + duration / 2;
    durations_[next_duration_] = duration;
    next_duration_ = (next_duration_ + 1) % kWindow;
    durations_count_ = std::min(durations_count_ + 1, kWindow);
    if (count_ >= kWarmUp) {
      const std::int64_t usual = median(durations_, durations_count_);
      const std::int64_t tolerance = std::max(kMinToleranceNs, usual / 10);
      if (duration > usual + tolerance) {
        return {usual_place(usual, begin_ns, end_ns, deadline_ns), true};
      }
    }
    offsets_[next_] = midpoint - deadline_ns;
    next_ = (next_ + 1) % kWindow;
    count_ = std::min(count_ + 1, kWindow);
    return {midpoint, false};
  }

  // Where the event of a transaction that failed (timed out: the device may have acted on the
  // request all the same) most likely was: its usual place, within [begin_ns, end_ns]. Learns
  // nothing. Without history, the midpoint.
  std::int64_t guess(std::int64_t begin_ns, std::int64_t end_ns,
                     std::int64_t deadline_ns) const noexcept {
    if (count_ < kWarmUp) return begin_ns + (end_ns - begin_ns) / 2;
    return usual_place(median(durations_, durations_count_), begin_ns, end_ns, deadline_ns);
  }

  void reset() noexcept { count_ = next_ = durations_count_ = next_duration_ = 0; }

 private:
  // The usual offset from the deadline, clamped into what the transaction's bounds allow for an
  // event `usual`/2 into a transaction of the usual duration.
  std::int64_t usual_place(std::int64_t usual, std::int64_t begin_ns, std::int64_t end_ns,
                           std::int64_t deadline_ns) const noexcept {
    const std::int64_t lo = begin_ns + usual / 2;
    const std::int64_t hi = std::max(lo, end_ns - usual / 2);
    return std::clamp(deadline_ns + median(offsets_, count_), lo, hi);
  }

  static std::int64_t median(const std::array<std::int64_t, kWindow>& values,
                             std::size_t n) noexcept {
    std::array<std::int64_t, kWindow> v = values;
    const auto mid = v.begin() + static_cast<std::ptrdiff_t>(n / 2);
    std::nth_element(v.begin(), mid, v.begin() + static_cast<std::ptrdiff_t>(n));
    return *mid;
  }

  std::array<std::int64_t, kWindow> durations_{};
  std::array<std::int64_t, kWindow> offsets_{};
  std::size_t next_ = 0;
  std::size_t count_ = 0;  // accepted transactions in offsets_
  std::size_t next_duration_ = 0;
  std::size_t durations_count_ = 0;
};

}  // namespace scp::drivers::modbus

#pragma once
// Bounded single-producer single-consumer ring of trivially copyable records. Wait-free on both
// sides, no allocation after construction. The real-time loop is the producer of the recorder's
// ring and the consumer of the command ring; neither side can ever block the other.

#include <array>
#include <atomic>
#include <cstddef>
#include <type_traits>

namespace scp::rt {

template <class T, std::size_t Capacity>
class SpscRing {
  static_assert(Capacity >= 2 && (Capacity & (Capacity - 1)) == 0, "capacity must be a power of 2");
  static_assert(std::is_trivially_copyable_v<T>);

 public:
  // Producer: false when full (the caller counts the drop or retries).
  bool try_push(const T& value) noexcept {
    const std::size_t head = head_.load(std::memory_order_relaxed);
    if (head - tail_cache_ == Capacity) {
      tail_cache_ = tail_.load(std::memory_order_acquire);
      if (head - tail_cache_ == Capacity) return false;
    }
    slots_[head & (Capacity - 1)] = value;
    head_.store(head + 1, std::memory_order_release);
    return true;
  }

  // Consumer: false when empty.
  bool try_pop(T& out) noexcept {
    const std::size_t tail = tail_.load(std::memory_order_relaxed);
    if (tail == head_cache_) {
      head_cache_ = head_.load(std::memory_order_acquire);
      if (tail == head_cache_) return false;
    }
    out = slots_[tail & (Capacity - 1)];
    tail_.store(tail + 1, std::memory_order_release);
    return true;
  }

  std::size_t size_approx() const noexcept {
    return head_.load(std::memory_order_acquire) - tail_.load(std::memory_order_acquire);
  }
  static constexpr std::size_t capacity() noexcept { return Capacity; }

 private:
  // Producer and consumer indices on separate cache lines so they do not false-share.
  alignas(64) std::atomic<std::size_t> head_{0};
  std::size_t tail_cache_ = 0;
  alignas(64) std::atomic<std::size_t> tail_{0};
  std::size_t head_cache_ = 0;
  alignas(64) std::array<T, Capacity> slots_{};
};

}  // namespace scp::rt

#pragma once
// Single-writer seqlock: the real-time loop publishes a trivially copyable snapshot every cycle and
// any number of readers on other threads copy it without ever making the writer wait.
//
// The writer bumps the sequence to odd, stores the payload, then bumps it to even. A reader retries
// while the sequence is odd or changed across its copy. The payload is copied word by word through
// relaxed atomics so that the concurrent copy is not a data race (ThreadSanitizer stays quiet and
// the compiler may not tear or cache it), following Boehm, "Can seqlocks get along with programming
// language memory models?" (2012).

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>

namespace scp::rt {

template <class T>
class Seqlock {
  static_assert(std::is_trivially_copyable_v<T>, "seqlock payloads are copied bytewise");
  static constexpr std::size_t kWords =
      (sizeof(T) + sizeof(std::uint64_t) - 1) / sizeof(std::uint64_t);

 public:
  Seqlock() noexcept {
    T empty{};
    store(empty);
  }

  // Writer side: one thread only (the loop). Wait-free.
  void store(const T& value) noexcept {
    std::uint64_t words[kWords] = {};
    std::memcpy(words, &value, sizeof(T));
    const std::uint64_t seq = seq_.load(std::memory_order_relaxed);
    seq_.store(seq + 1, std::memory_order_relaxed);
    std::atomic_thread_fence(std::memory_order_release);
    for (std::size_t i = 0; i < kWords; ++i) data_[i].store(words[i], std::memory_order_relaxed);
    seq_.store(seq + 2, std::memory_order_release);
  }

  // Reader side: any thread. Retries only while a store is in progress (a few hundred ns at most).
  T load() const noexcept {
    std::uint64_t words[kWords];
    for (;;) {
      const std::uint64_t before = seq_.load(std::memory_order_acquire);
      if (before & 1U) continue;
      for (std::size_t i = 0; i < kWords; ++i) words[i] = data_[i].load(std::memory_order_relaxed);
      std::atomic_thread_fence(std::memory_order_acquire);
      if (seq_.load(std::memory_order_relaxed) == before) break;
    }
    T value;
    std::memcpy(&value, words, sizeof(T));
    return value;
  }

  // One attempt, never waiting: false (and `out` untouched) while a store is in progress or one
  // overlapped the copy. For a real-time reader of a non-real-time writer: spinning in load()
  // could wait on a writer the reader itself preempted.
  bool try_load(T& out) const noexcept {
    std::uint64_t words[kWords];
    const std::uint64_t before = seq_.load(std::memory_order_acquire);
    if (before & 1U) return false;
    for (std::size_t i = 0; i < kWords; ++i) words[i] = data_[i].load(std::memory_order_relaxed);
    std::atomic_thread_fence(std::memory_order_acquire);
    if (seq_.load(std::memory_order_relaxed) != before) return false;
    std::memcpy(&out, words, sizeof(T));
    return true;
  }

  // Number of completed stores; lets a reader tell whether anything new was published.
  std::uint64_t version() const noexcept { return seq_.load(std::memory_order_acquire) / 2; }

 private:
  std::atomic<std::uint64_t> seq_{0};
  std::atomic<std::uint64_t> data_[kWords];
};

}  // namespace scp::rt

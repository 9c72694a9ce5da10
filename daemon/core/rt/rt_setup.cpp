#include "daemon/core/rt/rt_setup.hpp"

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <stdexcept>

#include "common/heap.hpp"

// AddressSanitizer and ThreadSanitizer reserve terabytes of shadow memory: mlockall() would try to
// fault all of it in. Sanitizer builds are for tests, so they skip the lock with a warning.
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define SCP_RT_SANITIZER_BUILD 1
#else
#define SCP_RT_SANITIZER_BUILD 0
#endif

namespace scp::rt {
namespace {

std::string errno_text(int err) {
  return std::strerror(err);
}

// Collects failures; throws at once when real-time operation was declared mandatory.
class Outcome {
 public:
  explicit Outcome(bool required) : required_(required) {}
  void fail(std::string message) {
    if (required_) {
      throw std::runtime_error(message + " (loop.realtime.required is true, so the daemon stops)");
    }
    warnings_.push_back(std::move(message));
  }
  std::vector<std::string> take() { return std::move(warnings_); }

 private:
  bool required_;
  std::vector<std::string> warnings_;
};

void set_priority(int priority, Outcome& outcome) {
  if (priority == 0) return;
  sched_param param{};
  param.sched_priority = priority;
  const int err = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);
  if (err != 0) {
    outcome.fail("cannot set SCHED_FIFO priority " + std::to_string(priority) + ": " +
                 errno_text(err) +
                 " — run as the systemd unit (it grants CAP_SYS_NICE and LimitRTPRIO=), raise "
                 "`ulimit -r`, or set loop.realtime.priority: 0");
  }
}

void set_affinity(const std::vector<int>& cpus, Outcome& outcome) {
  if (cpus.empty()) return;
  cpu_set_t set;
  CPU_ZERO(&set);
  for (int cpu : cpus) CPU_SET(static_cast<std::size_t>(cpu), &set);
  const int err = pthread_setaffinity_np(pthread_self(), sizeof(set), &set);
  if (err != 0) {
    std::string list;
    for (int cpu : cpus) {
      if (!list.empty()) list.push_back(',');
      list.append(std::to_string(cpu));
    }
    outcome.fail("cannot pin the loop thread to CPUs [" + list + "]: " + errno_text(err) +
                 " — list only CPUs this process may use (see `nproc`, the unit's CPUAffinity= "
                 "or the cgroup's cpuset) or leave loop.realtime.cpus empty");
  }
}

void touch_pages(volatile unsigned char* p, std::size_t bytes, std::size_t page) {
  for (std::size_t i = 0; i < bytes; i += page) p[i] = 0;
}

bool prefault_heap(std::size_t bytes, std::size_t page) {
  if (bytes == 0) return true;
  // malloc, not new: the point is to grow the heap that later allocations come from.
  auto* block = static_cast<unsigned char*>(std::malloc(bytes));
  if (block == nullptr) return false;
  touch_pages(block, bytes, page);
  std::free(block);
  return true;
}

// Touches `bytes` of stack below this frame in 16 KiB frames, so the first deep call on the hot
// path does not page-fault. noinline keeps each frame real.
constexpr std::size_t kStackChunk = 16 << 10;
[[gnu::noinline]] void prefault_stack_chunks(std::size_t chunks, std::size_t page) {
  volatile unsigned char frame[kStackChunk];
  touch_pages(frame, kStackChunk, page);
  if (chunks > 1) prefault_stack_chunks(chunks - 1, page);
  frame[0] = frame[kStackChunk - 1];  // keeps the frame alive across the recursive call
}

// Usable stack of the calling thread, or 0 if unknown.
std::size_t thread_stack_size() {
  pthread_attr_t attr;
  if (pthread_getattr_np(pthread_self(), &attr) != 0) return 0;
  std::size_t size = 0;
  void* addr = nullptr;
  pthread_attr_getstack(&attr, &addr, &size);
  pthread_attr_destroy(&attr);
  return size;
}

void lock_and_prefault(const RtSettings& s, Outcome& outcome) {
  const long page_size = sysconf(_SC_PAGESIZE);
  const std::size_t page = page_size > 0 ? static_cast<std::size_t>(page_size) : 4096;

  if (s.lock_memory && SCP_RT_SANITIZER_BUILD) {
    outcome.fail(
        "not locking memory: this is a sanitizer build (its shadow memory cannot be "
        "locked) — use a normal build for real-time operation");
  } else if (s.lock_memory) {
    if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0) {
      const int err = errno;
      outcome.fail(
          "cannot lock memory: " + errno_text(err) +
          " — add LimitMEMLOCK=infinity (and CAP_IPC_LOCK) to the unit, raise `ulimit -l`, "
          "or set loop.realtime.lock_memory: false");
    }
    // Keep freed memory in the heap and never satisfy malloc with a fresh mmap: after the
    // prefault below, allocations made during start-up come from locked, already-mapped pages.
    if (!keep_freed_memory()) {
      outcome.fail(
          "cannot configure malloc to keep memory (mallopt failed) — the C library "
          "is not glibc; set loop.realtime.lock_memory: false");
    }
  }
  if (!prefault_heap(s.prefault_heap_bytes, page)) {
    outcome.fail("cannot prefault " + std::to_string(s.prefault_heap_bytes >> 20) +
                 " MiB of heap: out of memory — lower loop.realtime.prefault_heap_bytes or raise "
                 "the unit's MemoryMax=");
  }
  std::size_t stack_bytes = s.prefault_stack_bytes;
  const std::size_t stack_size = thread_stack_size();
  // Leave a quarter of the stack for the frames above us; touching past the guard page would
  // crash the daemon, which a configuration value must never do.
  if (stack_size != 0 && stack_bytes > stack_size / 4 * 3) {
    outcome.fail("loop.realtime.prefault_stack_bytes (" + std::to_string(stack_bytes) +
                 ") exceeds three quarters of the loop thread's stack (" +
                 std::to_string(stack_size) + " bytes); prefaulting only that much — lower it");
    stack_bytes = stack_size / 4 * 3;
  }
  if (stack_bytes > 0) prefault_stack_chunks((stack_bytes + kStackChunk - 1) / kStackChunk, page);
}

}  // namespace

std::vector<std::string> apply_rt_settings(const RtSettings& settings) {
  if (settings.priority < 0 || settings.priority > 99) {
    throw std::invalid_argument(
        "loop.realtime.priority must be 0 (SCHED_OTHER) or 1..99 (SCHED_FIFO), got " +
        std::to_string(settings.priority));
  }
  for (int cpu : settings.cpus) {
    if (cpu < 0 || cpu >= CPU_SETSIZE) {
      throw std::invalid_argument("loop.realtime.cpus: CPU " + std::to_string(cpu) +
                                  " is out of range [0, " + std::to_string(CPU_SETSIZE - 1) + "]");
    }
  }
  Outcome outcome(settings.required);
  set_affinity(settings.cpus, outcome);
  // Memory before priority: prefaulting a large heap at SCHED_FIFO 80 would starve other threads
  // on this CPU for the duration.
  lock_and_prefault(settings, outcome);
  set_priority(settings.priority, outcome);
  return outcome.take();
}

bool set_default_thread_stack(std::size_t bytes) noexcept {
  pthread_attr_t attr;
  if (pthread_attr_init(&attr) != 0) return false;
  const bool ok =
      pthread_attr_setstacksize(&attr, bytes) == 0 && pthread_setattr_default_np(&attr) == 0;
  pthread_attr_destroy(&attr);
  return ok;
}

}  // namespace scp::rt

#pragma once
// Puts the calling thread into real-time shape before its first cycle: SCHED_FIFO priority, CPU
// affinity, locked and prefaulted memory. Each step that fails yields a warning that names the
// remedy (after realtime_tools' lock_memory() and linuxptp's sk.c), or throws when the user asked
// for real-time operation to be mandatory.

#include <cstddef>
#include <string>
#include <vector>

namespace scp::rt {

struct RtSettings {
  int priority = 80;        // SCHED_FIFO priority 1..99; 0 = stay SCHED_OTHER
  std::vector<int> cpus;    // CPUs the loop thread may run on; empty = leave the affinity alone
  bool lock_memory = true;  // mlockall(MCL_CURRENT | MCL_FUTURE) and keep freed memory in the heap
  std::size_t prefault_heap_bytes = std::size_t{64} << 20;
  std::size_t prefault_stack_bytes = std::size_t{512} << 10;
  bool required = false;  // true: any failure throws std::runtime_error instead of warning
};

// Call ON the loop thread, before its first cycle (it allocates and may take milliseconds).
// Returns one warning per step that failed (empty when everything took effect). Throws
// std::runtime_error on the first failure when settings.required, and std::invalid_argument for
// settings that can never work (priority out of 0..99, a negative or too large CPU number).
std::vector<std::string> apply_rt_settings(const RtSettings& settings);

// Stack size of the threads the daemon starts. glibc's default is RLIMIT_STACK, usually 8 MiB,
// and under mlockall(MCL_FUTURE) every byte of a new thread's stack is faulted in and locked. The
// loop thread's holds its prefault (RtSettings::prefault_stack_bytes, at most ¾ of the stack,
// rt_setup.cpp) and room above it; every other thread (socket server, refinement worker,
// recorder) gets several times what they were measured to touch (bench/results.md, memory).
// set_default_thread_stack() applies to the threads started after it; returns false if glibc
// refused.
inline constexpr std::size_t kLoopThreadStackBytes = std::size_t{768} << 10;
inline constexpr std::size_t kThreadStackBytes = std::size_t{256} << 10;
bool set_default_thread_stack(std::size_t bytes) noexcept;

}  // namespace scp::rt

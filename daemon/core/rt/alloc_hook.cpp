#include "daemon/core/rt/alloc_hook.hpp"

namespace scp::rt {

// Weak: a binary that links a counting definition (bench/loop_alloc_hook.cpp) replaces this one.
[[gnu::weak]] std::int64_t thread_allocation_count() noexcept {
  return -1;
}

}  // namespace scp::rt

// The counting definition of scp::rt::thread_allocation_count() for scp-estimatord-alloccount: the
// daemon, unchanged, linked with scp_alloc_counter (which replaces malloc and operator new), so
// that STATUS reports the loop thread's allocations after its real-time set-up (loop.allocations).

#include "daemon/core/rt/alloc_counter.hpp"
#include "daemon/core/rt/alloc_hook.hpp"

namespace {

// Armed before main(): every thread counts from its first allocation; the daemon subtracts the
// loop thread's count at start-up.
const bool g_armed = [] {
  scp::rt::alloc::arm();
  return true;
}();

}  // namespace

namespace scp::rt {

std::int64_t thread_allocation_count() noexcept {
  return static_cast<std::int64_t>(alloc::allocations_on_this_thread());
}

}  // namespace scp::rt

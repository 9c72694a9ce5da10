#pragma once
// How many heap allocations the calling thread has made, for the benchmark build that proves the
// loop thread allocates nothing after start-up. The production daemon has no counter: the weak
// definition in alloc_hook.cpp returns -1 ("not counted"). bench/loop_alloc_hook.cpp gives the
// strong definition, backed by scp_alloc_counter, for scp-estimatord-alloccount.

#include <cstdint>

namespace scp::rt {

// Allocations made by the calling thread so far, or -1 when this binary does not count them.
std::int64_t thread_allocation_count() noexcept;

}  // namespace scp::rt

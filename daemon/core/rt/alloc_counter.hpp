#pragma once
// Test and benchmark support (library scp_alloc_counter, never linked into the daemon): replaces
// the global operator new/delete to count allocations per thread, so a test can prove that the
// loop thread allocates nothing once it has started.
//
// Counting happens only while the global switch is armed, so allocations made by static
// initialisation, GoogleTest or start-up code before arm() do not count.
//
//   scp::rt::alloc::arm();
//   const auto before = scp::rt::alloc::allocations_on_this_thread();
//   ...hot path...
//   EXPECT_EQ(scp::rt::alloc::allocations_on_this_thread(), before);

#include <cstdint>

namespace scp::rt::alloc {

void arm() noexcept;
void disarm() noexcept;
bool armed() noexcept;

// Counts of operator new / operator delete calls (all forms) made by the calling thread while
// armed.
std::uint64_t allocations_on_this_thread() noexcept;
std::uint64_t deallocations_on_this_thread() noexcept;
std::uint64_t bytes_allocated_on_this_thread() noexcept;
// False in sanitizer builds, where only operator new/delete are counted (not malloc).
bool counts_malloc() noexcept;
// Totals over all threads while armed.
std::uint64_t allocations_total() noexcept;

// Counts the calling thread's allocations between construction and count().
class ScopedAllocationCount {
 public:
  ScopedAllocationCount() noexcept : start_(allocations_on_this_thread()) {}
  std::uint64_t count() const noexcept { return allocations_on_this_thread() - start_; }

 private:
  std::uint64_t start_;
};

}  // namespace scp::rt::alloc

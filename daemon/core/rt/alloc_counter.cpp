#include "daemon/core/rt/alloc_counter.hpp"

#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <new>

// Under AddressSanitizer/ThreadSanitizer the sanitizer runtime owns malloc, so only operator
// new/delete are replaced there. Otherwise the C allocation functions are replaced too (forwarding
// to glibc's __libc_* entry points): Eigen's dynamic matrices and many C libraries call malloc
// directly, and a real-time proof that missed them would be worthless.
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__) || !defined(__GLIBC__)
#define SCP_ALLOC_COUNT_MALLOC 0
#else
#define SCP_ALLOC_COUNT_MALLOC 1
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* __libc_memalign(std::size_t, std::size_t);
void __libc_free(void*);
}
#endif

namespace scp::rt::alloc {
namespace {

std::atomic<bool> g_armed{false};
std::atomic<std::uint64_t> g_total{0};
// Constant-initialised thread_locals: touching them from an allocation function never allocates.
thread_local std::uint64_t t_allocations = 0;
thread_local std::uint64_t t_deallocations = 0;
thread_local std::uint64_t t_bytes = 0;

void note_allocation(std::size_t size) noexcept {
  if (!g_armed.load(std::memory_order_relaxed)) return;
  ++t_allocations;
  t_bytes += size;
  g_total.fetch_add(1, std::memory_order_relaxed);
}

void note_deallocation(void* p) noexcept {
  if (p != nullptr && g_armed.load(std::memory_order_relaxed)) ++t_deallocations;
}

// operator new → these; when malloc itself is replaced, it does the counting.
void* allocate(std::size_t size) noexcept {
  if (!SCP_ALLOC_COUNT_MALLOC) note_allocation(size);
  return std::malloc(size == 0 ? 1 : size);
}

void* allocate_aligned(std::size_t size, std::align_val_t align) noexcept {
  if (!SCP_ALLOC_COUNT_MALLOC) note_allocation(size);
  void* p = nullptr;
  const auto alignment = static_cast<std::size_t>(align);
  if (posix_memalign(&p, alignment < sizeof(void*) ? sizeof(void*) : alignment,
                     size == 0 ? 1 : size) != 0) {
    return nullptr;
  }
  return p;
}

void release(void* p) noexcept {
  if (!SCP_ALLOC_COUNT_MALLOC) note_deallocation(p);
  std::free(p);
}

}  // namespace

void arm() noexcept {
  g_armed.store(true, std::memory_order_relaxed);
}
void disarm() noexcept {
  g_armed.store(false, std::memory_order_relaxed);
}
bool counts_malloc() noexcept {
  return SCP_ALLOC_COUNT_MALLOC != 0;
}
bool armed() noexcept {
  return g_armed.load(std::memory_order_relaxed);
}
std::uint64_t allocations_on_this_thread() noexcept {
  return t_allocations;
}
std::uint64_t deallocations_on_this_thread() noexcept {
  return t_deallocations;
}
std::uint64_t bytes_allocated_on_this_thread() noexcept {
  return t_bytes;
}
std::uint64_t allocations_total() noexcept {
  return g_total.load(std::memory_order_relaxed);
}

}  // namespace scp::rt::alloc

using scp::rt::alloc::allocate;
using scp::rt::alloc::allocate_aligned;
using scp::rt::alloc::note_allocation;
using scp::rt::alloc::note_deallocation;
using scp::rt::alloc::release;

#if SCP_ALLOC_COUNT_MALLOC
// The C allocation functions (glibc exports the __libc_* originals for exactly this purpose).
extern "C" {
void* malloc(std::size_t size) noexcept {
  note_allocation(size);
  return __libc_malloc(size);
}
void* calloc(std::size_t n, std::size_t size) noexcept {
  note_allocation(n * size);
  return __libc_calloc(n, size);
}
void* realloc(void* p, std::size_t size) noexcept {
  if (size != 0) note_allocation(size);
  if (p != nullptr && size == 0) note_deallocation(p);
  return __libc_realloc(p, size);
}
void free(void* p) noexcept {
  note_deallocation(p);
  __libc_free(p);
}
void* memalign(std::size_t align, std::size_t size) noexcept {
  note_allocation(size);
  return __libc_memalign(align, size);
}
void* aligned_alloc(std::size_t align, std::size_t size) noexcept {
  note_allocation(size);
  return __libc_memalign(align, size);
}
int posix_memalign(void** out, std::size_t align, std::size_t size) noexcept {
  if (align < sizeof(void*) || (align & (align - 1)) != 0) return EINVAL;
  note_allocation(size);
  void* p = __libc_memalign(align, size);
  if (p == nullptr) return ENOMEM;
  *out = p;
  return 0;
}
}
#endif

// The replaceable global allocation functions ([new.delete]); all forms, so nothing slips past.
void* operator new(std::size_t size) {
  if (void* p = allocate(size)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t size) {
  if (void* p = allocate(size)) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t size, const std::nothrow_t&) noexcept {
  return allocate(size);
}
void* operator new[](std::size_t size, const std::nothrow_t&) noexcept {
  return allocate(size);
}
void* operator new(std::size_t size, std::align_val_t align) {
  if (void* p = allocate_aligned(size, align)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t size, std::align_val_t align) {
  if (void* p = allocate_aligned(size, align)) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t size, std::align_val_t align, const std::nothrow_t&) noexcept {
  return allocate_aligned(size, align);
}
void* operator new[](std::size_t size, std::align_val_t align, const std::nothrow_t&) noexcept {
  return allocate_aligned(size, align);
}

void operator delete(void* p) noexcept {
  release(p);
}
void operator delete[](void* p) noexcept {
  release(p);
}
void operator delete(void* p, std::size_t) noexcept {
  release(p);
}
void operator delete[](void* p, std::size_t) noexcept {
  release(p);
}
void operator delete(void* p, const std::nothrow_t&) noexcept {
  release(p);
}
void operator delete[](void* p, const std::nothrow_t&) noexcept {
  release(p);
}
void operator delete(void* p, std::align_val_t) noexcept {
  release(p);
}
void operator delete[](void* p, std::align_val_t) noexcept {
  release(p);
}
void operator delete(void* p, std::size_t, std::align_val_t) noexcept {
  release(p);
}
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept {
  release(p);
}
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept {
  release(p);
}
void operator delete[](void* p, std::align_val_t, const std::nothrow_t&) noexcept {
  release(p);
}

#pragma once
// How the daemon has glibc's malloc treat freed memory: kept in the heap for the next allocation,
// never handed back to the kernel, and no allocation served by a fresh mmap. A refinement pass
// allocates and frees the same few large buffers (its validation's block matrices) every time;
// handed back, each pass faults them in again, which a paravirtualized machine makes dear
// (docs/numerics.md, "The one-step rule and the heap"). The real-time set-up needs the same for
// its locked, prefaulted heap.

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace scp {

// False where the C library is not glibc or refused (the daemon then runs as before, slower).
inline bool keep_freed_memory() noexcept {
#if defined(__GLIBC__)
  return mallopt(M_TRIM_THRESHOLD, -1) == 1 && mallopt(M_MMAP_MAX, 0) == 1;
#else
  return false;
#endif
}

}  // namespace scp

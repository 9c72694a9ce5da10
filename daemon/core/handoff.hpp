#pragma once
// What the loop hands to the refinement: every sample it fed the estimator, through a lock-free
// ring the loop never waits on. The loop knows nothing else of the refinement (docs/protocol.md,
// "refined").

#include <cstddef>
#include <cstdint>

#include "daemon/core/rt/spsc_ring.hpp"
#include "refine/fit.hpp"

namespace scp::daemon {

struct HandOff {
  scp::refine::WindowSample sample;
  // The loop changes it whenever its samples stop being one contiguous run the model can be
  // simulated through: a sample dropped because this ring was full, an estimator reset, the loop
  // leaving RUNNING. A change starts a new window.
  std::uint64_t segment = 0;
};

// 16 s at 1 kHz (768 KiB, locked): the worker drains it between fits, so a fit may take that long
// before samples are dropped (counted, STATUS refine.handoff_dropped) and the window restarts.
// Measured: a 300 s window at 1 kHz takes 1.2 s CPU, 1-8 s wall on a loaded 2-core machine, so 2×
// the worst wall time seen. It was 65 s (3 MiB): with the window it kept the default config's RSS
// above 24 MiB (README, memory).
inline constexpr std::size_t kHandOffCapacity = 16384;
using HandOffRing = rt::SpscRing<HandOff, kHandOffCapacity>;

}  // namespace scp::daemon

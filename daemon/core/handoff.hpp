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

// The worker drains the ring between fits, so a fit may take as long as the ring holds (16 s at
// 1 kHz) before samples are dropped (counted, STATUS refine.handoff_dropped) and the window
// restarts: twice the longest fit measured on a loaded machine, and no more, since the ring is
// locked memory like the window (bench/results.md, memory).
inline constexpr std::size_t kHandOffCapacity = 16384;
using HandOffRing = rt::SpscRing<HandOff, kHandOffCapacity>;

}  // namespace scp::daemon

#pragma once
// A new excitation for the running loop (SIGHUP), handed over without a lock or an allocation on
// the loop thread. The main thread builds the Excitation (the only allocation), the loop takes a
// pointer from one SPSC ring and gives the one it stops using back on another; the main thread
// frees it later. Each side only pushes to one ring and pops from the other, as with commands.

#include <cstdint>
#include <memory>
#include <vector>

#include "daemon/core/rt/spsc_ring.hpp"
#include "excitation/excitation.hpp"

namespace scp::daemon {

struct ExcitationUpdate {
  const excitation::Excitation* next = nullptr;  // null: keep the excitation
  std::int8_t enabled = -1;                      // -1 keep, 0 off, 1 on (excitation.enabled)
};

class ExcitationExchange {
 public:
  // Main thread. False (nothing handed over) when the loop has not taken the earlier offers yet.
  bool offer(std::unique_ptr<excitation::Excitation> next, std::int8_t enabled);
  // Main thread: frees the excitations the loop has given back.
  void collect();

  // Loop thread, real-time safe.
  bool take(ExcitationUpdate& out) noexcept { return incoming_.try_pop(out); }
  void retire(const excitation::Excitation* old) noexcept {
    // Never full: at most kMaxOwned excitations exist, the ring holds twice as many.
    (void)retired_.try_push(old);
  }

 private:
  static constexpr std::size_t kMaxOwned = 4;
  rt::SpscRing<ExcitationUpdate, 4> incoming_;
  rt::SpscRing<const excitation::Excitation*, 8> retired_;
  // Main thread only: every excitation handed over and not yet given back, the loop's current one
  // included. Freed with the exchange, which outlives the loop.
  std::vector<std::unique_ptr<excitation::Excitation>> owned_;
};

}  // namespace scp::daemon

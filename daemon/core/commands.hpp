#pragma once
// Commands travel from the socket server (the single producer) to the loop through an SPSC ring;
// the loop takes them at the start of a cycle and answers the last with the CommandAck it
// publishes.

#include <cstddef>
#include <cstdint>

#include "daemon/core/rt/spsc_ring.hpp"

namespace scp::daemon {

enum class CommandKind : std::uint8_t { reset, excitation_on, excitation_off, clear_fault };

struct Command {
  std::uint64_t seq = 0;
  CommandKind kind = CommandKind::reset;
};

inline constexpr std::size_t kCommandRingSize = 64;
using CommandRing = rt::SpscRing<Command, kCommandRingSize>;

}  // namespace scp::daemon

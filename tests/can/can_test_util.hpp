#pragma once
// A socketpair standing in for a CAN bus: each end carries one struct can_frame per message.

#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <stdexcept>

namespace scp::drivers::can::test {

inline std::array<int, 2> frame_pair() {
  int fds[2];
  if (::socketpair(AF_UNIX, SOCK_SEQPACKET, 0, fds) != 0) throw std::runtime_error("socketpair");
  return {fds[0], fds[1]};
}

}  // namespace scp::drivers::can::test

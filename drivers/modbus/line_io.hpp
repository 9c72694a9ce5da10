#pragma once
// The wait both transactions (TCP and RTU) bound themselves with: one deadline on
// CLOCK_MONOTONIC (common/clock.hpp), re-read after every wake-up, so that time lost anywhere (a
// preemption, a syscall that blocked in the kernel) shortens the next wait instead of adding to the
// total.

#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>

#include "common/clock.hpp"

namespace scp::drivers::modbus {

// Waits until `fd` is readable or `deadline_ns` passes: 1 readable, 0 deadline, −errno.
inline int wait_readable(int fd, std::int64_t deadline_ns) noexcept {
  for (;;) {
    const std::int64_t left = deadline_ns - clock::monotonic_ns();
    if (left <= 0) return 0;
    const timespec ts = clock::to_timespec(left);
    pollfd p{fd, POLLIN, 0};
    const int rc = ppoll(&p, 1, &ts, nullptr);
    if (rc > 0) return 1;
    if (rc == 0) continue;  // re-check the clock: ppoll may return a little early
    if (errno != EINTR) return -errno;
  }
}

// Hands a whole request to `fd` without blocking: 0, or an errno-style code. `socket`: send()
// without SIGPIPE (a peer that closed), else write() (a serial port).
inline int send_frame_bytes(int fd, const std::uint8_t* frame, int len, bool socket) noexcept {
  int sent = 0;
  while (sent < len) {
    const auto left = static_cast<std::size_t>(len - sent);
    const ssize_t n = socket ? ::send(fd, frame + sent, left, MSG_NOSIGNAL | MSG_DONTWAIT)
                             : ::write(fd, frame + sent, left);
    if (n > 0) {
      sent += static_cast<int>(n);
    } else if (n < 0 && errno == EINTR) {
      continue;
    } else {
      // A full queue on a frame this short: the peer (or the port) stopped taking bytes long ago.
      return n < 0 && errno != EAGAIN ? errno : ETIMEDOUT;
    }
  }
  return 0;
}

}  // namespace scp::drivers::modbus

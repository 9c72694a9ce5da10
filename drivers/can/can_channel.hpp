#pragma once
// A CAN endpoint over a file descriptor: a real CAN_RAW socket, or anything else carrying
// struct can_frame / canfd_frame records one per message (a socketpair in tests, an inherited fd).

#include <linux/can.h>

#include <cstdint>
#include <span>
#include <string>

namespace scp::drivers::can {

enum class RxStatus : std::uint8_t {
  frame,      // one frame received
  empty,      // nothing pending (EAGAIN)
  malformed,  // a record of the wrong size: dropped
  down,       // ENETDOWN: the interface is down
  error,      // any other error; errno in last_errno()
};

enum class TxStatus : std::uint8_t {
  sent,
  queue_full,  // EAGAIN / ENOBUFS: the transmit queue is full (bus saturated or no ACK)
  down,        // ENETDOWN
  error,
};

class CanChannel {
 public:
  CanChannel() = default;
  // Takes ownership of fd and makes it non-blocking. Throws DriverError if fd is invalid.
  explicit CanChannel(int fd);
  ~CanChannel();
  CanChannel(CanChannel&& other) noexcept;
  CanChannel& operator=(CanChannel&& other) noexcept;
  CanChannel(const CanChannel&) = delete;
  CanChannel& operator=(const CanChannel&) = delete;

  bool valid() const noexcept { return fd_ >= 0; }
  int fd() const noexcept { return fd_; }
  void close() noexcept;

  // Non-blocking receive of one frame. `frame` holds classic and FD frames alike; is_fd tells
  // which size arrived.
  RxStatus receive(canfd_frame& frame, bool& is_fd) noexcept;
  // Non-blocking send; a classic frame when !is_fd (16-byte record), else a 72-byte record.
  TxStatus send(const canfd_frame& frame, bool is_fd) noexcept;

  int last_errno() const noexcept { return last_errno_; }
  // Frames the kernel dropped because our receive queue was full (SO_RXQ_OVFL; CAN sockets only).
  std::uint32_t kernel_drops() const noexcept { return kernel_drops_; }

 private:
  int fd_ = -1;
  int last_errno_ = 0;
  std::uint32_t kernel_drops_ = 0;
};

// The descriptor named by an interface of the form "fd:N" (N ≥ 0: a socket inherited from the
// process that started us, e.g. one end of a socketpair, or a systemd socket), or -1 when the
// interface is an ordinary name. Throws DriverError for "fd:" followed by anything but digits.
int inherited_fd(const std::string& interface);

// Creates a CAN_RAW socket on `ifname` that receives only `ids` (each with CAN_EFF_FLAG for a
// 29-bit id) and every error class except CAN_ERR_BUSERROR, enables FD frames when fd_mode, asks
// for drop counts (SO_RXQ_OVFL), and binds. Throws DriverError naming the remedy.
CanChannel open_socketcan(const std::string& ifname, std::span<const canid_t> ids, bool fd_mode);

}  // namespace scp::drivers::can

#include "drivers/can/can_channel.hpp"

#include <fcntl.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <string_view>
#include <utility>
#include <vector>

#include "drivers/driver.hpp"

namespace scp::drivers::can {

int inherited_fd(const std::string& interface) {
  static constexpr std::string_view kPrefix = "fd:";
  if (interface.rfind(kPrefix, 0) != 0) return -1;
  const std::string digits = interface.substr(kPrefix.size());
  if (digits.empty() || digits.size() > 6 ||
      digits.find_first_not_of("0123456789") != std::string::npos) {
    throw DriverError("CAN interface '" + interface +
                      "': an inherited descriptor is written fd:N with N a number, e.g. fd:3");
  }
  return std::stoi(digits);
}

CanChannel::CanChannel(int fd) : fd_(fd) {
  const int flags = fd < 0 ? -1 : ::fcntl(fd, F_GETFL);
  if (flags < 0 || ::fcntl(fd, F_SETFL, flags | O_NONBLOCK) < 0) {
    fd_ = -1;
    throw DriverError("CAN: file descriptor " + std::to_string(fd) + " is not usable (" +
                      std::strerror(errno) +
                      "); pass an open socket carrying struct can_frame records");
  }
}

CanChannel::~CanChannel() {
  close();
}

CanChannel::CanChannel(CanChannel&& other) noexcept
    : fd_(std::exchange(other.fd_, -1)),
      last_errno_(other.last_errno_),
      kernel_drops_(other.kernel_drops_) {}

CanChannel& CanChannel::operator=(CanChannel&& other) noexcept {
  if (this != &other) {
    close();
    fd_ = std::exchange(other.fd_, -1);
    last_errno_ = other.last_errno_;
    kernel_drops_ = other.kernel_drops_;
  }
  return *this;
}

void CanChannel::close() noexcept {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

RxStatus CanChannel::receive(canfd_frame& frame, bool& is_fd) noexcept {
  if (fd_ < 0) {
    last_errno_ = EBADF;
    return RxStatus::error;
  }
  iovec iov{&frame, sizeof frame};
  // Room for the SO_RXQ_OVFL counter; on the stack, so no allocation per call.
  alignas(cmsghdr) char control[CMSG_SPACE(sizeof(std::uint32_t))];
  msghdr msg{};
  msg.msg_iov = &iov;
  msg.msg_iovlen = 1;
  msg.msg_control = control;
  msg.msg_controllen = sizeof control;
  const ssize_t n = ::recvmsg(fd_, &msg, MSG_DONTWAIT);
  if (n < 0) {
    last_errno_ = errno;
    if (errno == EAGAIN || errno == EWOULDBLOCK) return RxStatus::empty;
    if (errno == EINTR) return RxStatus::empty;
    // ENETDOWN from a CAN socket; the others when the peer of an inherited socket went away.
    if (errno == ENETDOWN || errno == ECONNRESET || errno == ENOTCONN || errno == EPIPE) {
      return RxStatus::down;
    }
    return RxStatus::error;
  }
  for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c != nullptr; c = CMSG_NXTHDR(&msg, c)) {
    if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SO_RXQ_OVFL) {
      std::memcpy(&kernel_drops_, CMSG_DATA(c), sizeof kernel_drops_);
    }
  }
  if (n == static_cast<ssize_t>(CAN_MTU)) {
    is_fd = false;
    if (frame.len > CAN_MAX_DLEN) return RxStatus::malformed;
    return RxStatus::frame;
  }
  if (n == static_cast<ssize_t>(CANFD_MTU)) {
    is_fd = true;
    if (frame.len > CANFD_MAX_DLEN) return RxStatus::malformed;
    return RxStatus::frame;
  }
  // A zero-length read on a stream/seqpacket socket means the peer closed.
  if (n == 0) {
    last_errno_ = ENOTCONN;
    return RxStatus::down;
  }
  return RxStatus::malformed;
}

TxStatus CanChannel::send(const canfd_frame& frame, bool is_fd) noexcept {
  if (fd_ < 0) {
    last_errno_ = EBADF;
    return TxStatus::error;
  }
  const std::size_t size = is_fd ? CANFD_MTU : CAN_MTU;
  const ssize_t n = ::send(fd_, &frame, size, MSG_DONTWAIT | MSG_NOSIGNAL);
  if (n == static_cast<ssize_t>(size)) return TxStatus::sent;
  last_errno_ = n < 0 ? errno : EMSGSIZE;
  if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == ENOBUFS)) {
    return TxStatus::queue_full;
  }
  if (n < 0 && (errno == ENETDOWN || errno == ECONNRESET || errno == ENOTCONN || errno == EPIPE)) {
    return TxStatus::down;
  }
  return TxStatus::error;
}

CanChannel open_socketcan(const std::string& ifname, std::span<const canid_t> ids, bool fd_mode) {
  const int fd = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
  if (fd < 0) {
    const int e = errno;
    if (e == EAFNOSUPPORT || e == EPROTONOSUPPORT) {
      throw DriverError(std::string("CAN: this kernel has no SocketCAN support (") +
                        std::strerror(e) +
                        "); load it with `modprobe can_raw` (and `modprobe vcan` for a virtual "
                        "bus), or set driver.type to sim or modbus");
    }
    throw DriverError(std::string("CAN: cannot create a CAN_RAW socket: ") + std::strerror(e));
  }
  CanChannel channel(fd);  // owns fd from here on; closes it if we throw below

  if (ifname.empty() || ifname.size() >= IFNAMSIZ) {
    throw DriverError("CAN: interface name '" + ifname + "' is invalid (1..15 characters)");
  }
  const unsigned index = ::if_nametoindex(ifname.c_str());
  if (index == 0) {
    throw DriverError("CAN: no interface '" + ifname +
                      "'; check `ip link show`, or for a virtual bus: `modprobe vcan && ip link "
                      "add dev " +
                      ifname + " type vcan && ip link set " + ifname + " up`");
  }

  // Exactly the identifiers in use: the kernel drops everything else before it reaches us.
  std::vector<can_filter> filters;
  for (canid_t id : ids) {
    const bool ext = (id & CAN_EFF_FLAG) != 0;
    filters.push_back({id, (ext ? CAN_EFF_MASK : CAN_SFF_MASK) | CAN_EFF_FLAG | CAN_RTR_FLAG});
  }
  if (::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_FILTER, filters.empty() ? nullptr : filters.data(),
                   static_cast<socklen_t>(filters.size() * sizeof(can_filter))) < 0) {
    throw DriverError(std::string("CAN: CAN_RAW_FILTER failed: ") + std::strerror(errno));
  }
  // Bus errors arrive on every corrupted bit and would flood the queue; the states they lead to
  // (warning, passive, bus-off) still arrive through the controller and bus-off classes.
  const can_err_mask_t err_mask = CAN_ERR_MASK & ~CAN_ERR_BUSERROR;
  if (::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &err_mask, sizeof err_mask) < 0) {
    throw DriverError(std::string("CAN: CAN_RAW_ERR_FILTER failed: ") + std::strerror(errno));
  }
  if (fd_mode) {
    const int on = 1;
    if (::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof on) < 0) {
      throw DriverError("CAN: this kernel refuses CAN FD frames (" +
                        std::string(std::strerror(errno)) + "); set can.fd: false");
    }
  }
  const int on = 1;
  // Best effort: older kernels lack it, and the driver then counts only its own drops.
  (void)::setsockopt(fd, SOL_SOCKET, SO_RXQ_OVFL, &on, sizeof on);

  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = static_cast<int>(index);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0) {
    throw DriverError("CAN: cannot bind to '" + ifname + "': " + std::strerror(errno) +
                      "; is it up? `ip link set " + ifname + " up type can bitrate 500000`");
  }
  if (fd_mode) {
    // An FD socket on a classic-only controller would fail at the first send; say so now.
    ifreq ifr{};
    std::strncpy(ifr.ifr_name, ifname.c_str(), IFNAMSIZ - 1);
    if (::ioctl(fd, SIOCGIFMTU, &ifr) == 0 && ifr.ifr_mtu != static_cast<int>(CANFD_MTU)) {
      throw DriverError("CAN: '" + ifname + "' is not CAN FD capable (MTU " +
                        std::to_string(ifr.ifr_mtu) + "); set can.fd: false, or `ip link set " +
                        ifname + " up type can bitrate 500000 dbitrate 2000000 fd on`");
    }
  }
  return channel;
}

}  // namespace scp::drivers::can

#include "drivers/modbus/tcp_transaction.hpp"

#include <modbus/modbus.h>
#include <sys/socket.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <ctime>

#include "drivers/modbus/line_io.hpp"

namespace scp::drivers::modbus {

namespace {

constexpr int kHeader = 7;  // transaction id, protocol id, length (2 bytes each), unit id

// A kernel receive stamp (CLOCK_REALTIME) on CLOCK_MONOTONIC: the two clocks' offset is read
// now, between two monotonic readings; it moves only when the wall clock is stepped or slewed,
// by far less than a microsecond over the milliseconds since the segment arrived.
std::int64_t realtime_to_monotonic_ns(const timespec& real) noexcept {
  timespec m0{}, r{}, m1{};
  clock_gettime(CLOCK_MONOTONIC, &m0);
  clock_gettime(CLOCK_REALTIME, &r);
  clock_gettime(CLOCK_MONOTONIC, &m1);
  const std::int64_t mono_now = clock::to_ns(m0) + (clock::to_ns(m1) - clock::to_ns(m0)) / 2;
  return clock::to_ns(real) - clock::to_ns(r) + mono_now;
}

}  // namespace

bool enable_receive_stamps(int fd) noexcept {
  const int on = 1;
  return setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof on) == 0;
}

int TcpTransaction::take_frame(std::uint16_t& tid, int& unit,
                               std::array<std::uint8_t, kMaxPdu>& pdu, int& pdu_len) noexcept {
  if (rx_len_ < kHeader) return 0;
  const int protocol = (rx_[2] << 8) | rx_[3];
  const int length = (rx_[4] << 8) | rx_[5];  // unit id + PDU
  if (protocol != 0 || length < 2 || length > kMaxPdu + 1) return -1;
  const int frame = 6 + length;
  if (rx_len_ < frame) return 0;
  tid = static_cast<std::uint16_t>((rx_[0] << 8) | rx_[1]);
  unit = rx_[6];
  pdu_len = length - 1;
  std::memcpy(pdu.data(), rx_.data() + kHeader, static_cast<std::size_t>(pdu_len));
  std::memmove(rx_.data(), rx_.data() + frame, static_cast<std::size_t>(rx_len_ - frame));
  rx_len_ -= frame;
  return 1;
}

int TcpTransaction::send_frame(int fd, int unit, std::uint16_t tid, const std::uint8_t* pdu,
                               int pdu_len) noexcept {
  std::array<std::uint8_t, kMaxFrame> frame{};
  frame[0] = static_cast<std::uint8_t>(tid >> 8);
  frame[1] = static_cast<std::uint8_t>(tid & 0xFF);
  frame[4] = static_cast<std::uint8_t>((pdu_len + 1) >> 8);
  frame[5] = static_cast<std::uint8_t>((pdu_len + 1) & 0xFF);
  frame[6] = static_cast<std::uint8_t>(unit);
  std::memcpy(frame.data() + kHeader, pdu, static_cast<std::size_t>(pdu_len));
  const int total = kHeader + pdu_len;
  sent_ns_ = clock::monotonic_ns();
  return send_frame_bytes(fd, frame.data(), total, true);
}

int TcpTransaction::receive(int fd) noexcept {
  iovec iov{rx_.data() + rx_len_, rx_.size() - static_cast<std::size_t>(rx_len_)};
  alignas(cmsghdr) std::array<char, CMSG_SPACE(sizeof(timespec)) * 2> control{};
  msghdr msg{};
  msg.msg_iov = &iov;
  msg.msg_iovlen = 1;
  msg.msg_control = control.data();
  msg.msg_controllen = control.size();
  const ssize_t n = ::recvmsg(fd, &msg, MSG_DONTWAIT);
  if (n == 0) return ECONNRESET;
  if (n < 0) return errno == EINTR || errno == EAGAIN ? 0 : errno;
  rx_len_ += static_cast<int>(n);
  last_recv_ns_ = 0;
  for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c != nullptr; c = CMSG_NXTHDR(&msg, c)) {
    if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SCM_TIMESTAMPNS &&
        c->cmsg_len >= CMSG_LEN(sizeof(timespec))) {
      timespec ts{};
      std::memcpy(&ts, CMSG_DATA(c), sizeof ts);
      if (ts.tv_sec != 0 || ts.tv_nsec != 0) last_recv_ns_ = realtime_to_monotonic_ns(ts);
    }
  }
  return 0;
}

int TcpTransaction::transact(int fd, int unit, const std::uint8_t* pdu, int pdu_len,
                             std::array<std::uint8_t, kMaxPdu>& reply, int& reply_len,
                             double timeout_s, std::int64_t not_after_ns) noexcept {
  if (fd < 0) return EBADF;
  if (pdu_len < 1 || pdu_len > kMaxPdu) return EINVAL;
  reply_ns_ = 0;
  const std::uint16_t tid = next_tid_++;
  if (next_tid_ == 0) next_tid_ = 1;
  if (const int err = send_frame(fd, unit, tid, pdu, pdu_len); err != 0) return err;
  const std::int64_t deadline =
      std::min(sent_ns_ + static_cast<std::int64_t>(timeout_s * 1e9), not_after_ns);
  for (;;) {
    std::uint16_t got_tid = 0;
    int got_unit = 0;
    for (;;) {
      const int taken = take_frame(got_tid, got_unit, reply, reply_len);
      if (taken < 0) return EMBBADDATA;
      if (taken == 0) break;
      if (got_tid != tid) {
        ++late_;  // the answer to a request that timed out earlier: not ours, drop it
        continue;
      }
      if (got_unit != unit) return EMBBADDATA;
      // The frame was complete with the latest bytes read (or earlier: then this stamp is
      // late by at most those bytes' delay, never early).
      reply_ns_ = last_recv_ns_;
      return 0;
    }
    const int ready = wait_readable(fd, deadline);
    if (ready == 0) return ETIMEDOUT;
    if (ready < 0) return -ready;
    if (const int err = receive(fd); err != 0) return err;
  }
}

}  // namespace scp::drivers::modbus

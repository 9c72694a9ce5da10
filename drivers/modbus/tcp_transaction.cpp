#include "drivers/modbus/tcp_transaction.hpp"

#include <modbus/modbus.h>
#include <poll.h>
#include <sys/socket.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <ctime>

namespace scp::drivers::modbus {

namespace {

constexpr int kHeader = 7;  // transaction id, protocol id, length (2 bytes each), unit id

double monotonic_s() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<double>(ts.tv_sec) + static_cast<double>(ts.tv_nsec) * 1e-9;
}

// Waits until `fd` is readable or the deadline passes: 1 readable, 0 timeout, -errno.
int wait_readable(int fd, double deadline) noexcept {
  for (;;) {
    const double left = deadline - monotonic_s();
    if (left <= 0.0) return 0;
    timespec ts{};
    ts.tv_sec = static_cast<time_t>(left);
    ts.tv_nsec = static_cast<long>((left - static_cast<double>(ts.tv_sec)) * 1e9);
    pollfd p{fd, POLLIN, 0};
    const int rc = ppoll(&p, 1, &ts, nullptr);
    if (rc > 0) return 1;
    if (rc == 0) continue;  // re-check the clock: ppoll may return a little early
    if (errno != EINTR) return -errno;
  }
}

// A kernel receive stamp (CLOCK_REALTIME) on CLOCK_MONOTONIC: the two clocks' offset is read
// now, between two monotonic readings; it moves only when the wall clock is stepped or slewed,
// by far less than a microsecond over the milliseconds since the segment arrived.
std::int64_t realtime_to_monotonic_ns(const timespec& real) noexcept {
  timespec m0{}, r{}, m1{};
  clock_gettime(CLOCK_MONOTONIC, &m0);
  clock_gettime(CLOCK_REALTIME, &r);
  clock_gettime(CLOCK_MONOTONIC, &m1);
  const auto ns = [](const timespec& t) {
    return static_cast<std::int64_t>(t.tv_sec) * 1'000'000'000 + t.tv_nsec;
  };
  const std::int64_t mono_now = ns(m0) + (ns(m1) - ns(m0)) / 2;
  return ns(real) - ns(r) + mono_now;
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

int TcpTransaction::transact(int fd, int unit, const std::uint8_t* pdu, int pdu_len,
                             std::array<std::uint8_t, kMaxPdu>& reply, int& reply_len,
                             double timeout_s) noexcept {
  if (fd < 0) return EBADF;
  if (pdu_len < 1 || pdu_len > kMaxPdu) return EINVAL;
  reply_ns_ = 0;
  const std::uint16_t tid = next_tid_++;
  if (next_tid_ == 0) next_tid_ = 1;
  std::array<std::uint8_t, kMaxFrame> frame{};
  frame[0] = static_cast<std::uint8_t>(tid >> 8);
  frame[1] = static_cast<std::uint8_t>(tid & 0xFF);
  frame[4] = static_cast<std::uint8_t>((pdu_len + 1) >> 8);
  frame[5] = static_cast<std::uint8_t>((pdu_len + 1) & 0xFF);
  frame[6] = static_cast<std::uint8_t>(unit);
  std::memcpy(frame.data() + kHeader, pdu, static_cast<std::size_t>(pdu_len));
  const int total = kHeader + pdu_len;
  int sent = 0;
  while (sent < total) {
    const ssize_t n = ::send(fd, frame.data() + sent, static_cast<std::size_t>(total - sent),
                             MSG_NOSIGNAL | MSG_DONTWAIT);
    if (n > 0) {
      sent += static_cast<int>(n);
    } else if (n < 0 && errno == EINTR) {
      continue;
    } else {
      // A full send buffer on a 12-byte request means the peer stopped reading long ago.
      return n < 0 && errno != EAGAIN ? errno : ETIMEDOUT;
    }
  }

  const double deadline = monotonic_s() + timeout_s;
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
    iovec iov{rx_.data() + rx_len_, rx_.size() - static_cast<std::size_t>(rx_len_)};
    alignas(cmsghdr) std::array<char, CMSG_SPACE(sizeof(timespec)) * 2> control{};
    msghdr msg{};
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    msg.msg_control = control.data();
    msg.msg_controllen = control.size();
    const ssize_t n = ::recvmsg(fd, &msg, MSG_DONTWAIT);
    if (n == 0) return ECONNRESET;
    if (n < 0) {
      if (errno == EINTR || errno == EAGAIN) continue;
      return errno;
    }
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
  }
}

int read_registers_pdu(bool input_table, int address, int count, std::uint8_t* pdu) noexcept {
  pdu[0] = input_table ? 0x04 : 0x03;
  pdu[1] = static_cast<std::uint8_t>(address >> 8);
  pdu[2] = static_cast<std::uint8_t>(address & 0xFF);
  pdu[3] = static_cast<std::uint8_t>(count >> 8);
  pdu[4] = static_cast<std::uint8_t>(count & 0xFF);
  return 5;
}

namespace {
int exception_or_bad(int function, const std::uint8_t* reply, int reply_len) noexcept {
  if (reply_len == 2 && reply[0] == (function | 0x80) && reply[1] >= 1 && reply[1] <= 11) {
    return MODBUS_ENOBASE + reply[1];
  }
  return EMBBADDATA;
}
}  // namespace

int check_read_reply(bool input_table, int count, const std::uint8_t* reply, int reply_len,
                     std::uint16_t* registers) noexcept {
  const int function = input_table ? 0x04 : 0x03;
  if (reply_len < 1 || reply[0] != function) return exception_or_bad(function, reply, reply_len);
  if (reply_len != 2 + 2 * count || reply[1] != 2 * count) return EMBBADDATA;
  for (int i = 0; i < count; ++i) {
    registers[i] = static_cast<std::uint16_t>((reply[2 + 2 * i] << 8) | reply[3 + 2 * i]);
  }
  return 0;
}

int write_registers_pdu(int function, int address, int count, const std::uint16_t* values,
                        std::uint8_t* pdu) noexcept {
  pdu[0] = static_cast<std::uint8_t>(function);
  pdu[1] = static_cast<std::uint8_t>(address >> 8);
  pdu[2] = static_cast<std::uint8_t>(address & 0xFF);
  if (function == 0x06) {
    pdu[3] = static_cast<std::uint8_t>(values[0] >> 8);
    pdu[4] = static_cast<std::uint8_t>(values[0] & 0xFF);
    return 5;
  }
  pdu[3] = static_cast<std::uint8_t>(count >> 8);
  pdu[4] = static_cast<std::uint8_t>(count & 0xFF);
  pdu[5] = static_cast<std::uint8_t>(2 * count);
  for (int i = 0; i < count; ++i) {
    pdu[6 + 2 * i] = static_cast<std::uint8_t>(values[i] >> 8);
    pdu[7 + 2 * i] = static_cast<std::uint8_t>(values[i] & 0xFF);
  }
  return 6 + 2 * count;
}

int check_write_reply(const std::uint8_t* request, int request_len, const std::uint8_t* reply,
                      int reply_len) noexcept {
  (void)request_len;
  const int function = request[0];
  if (reply_len < 1 || reply[0] != function) return exception_or_bad(function, reply, reply_len);
  // Function 6 echoes address and value, 16 echoes address and count: the first 4 data bytes.
  if (reply_len != 5 || std::memcmp(reply + 1, request + 1, 4) != 0) return EMBBADDATA;
  return 0;
}

}  // namespace scp::drivers::modbus

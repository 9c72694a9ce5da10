#include "drivers/modbus/rtu_transaction.hpp"

#include <modbus/modbus.h>
#include <sys/epoll.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "drivers/modbus/line_io.hpp"

namespace scp::drivers::modbus {

namespace {

// The whole frame's length once its first bytes are known (address, function, byte count), 0
// while more are needed to tell, −1 for a function this driver never asks for.
int expected_frame_length(const std::uint8_t* frame, int len) noexcept {
  if (len < 2) return 0;
  const int function = frame[1];
  if (function & 0x80) return 5;  // address, function | 0x80, exception code, CRC
  switch (function) {
    case 0x03:
    case 0x04:
      return len < 3 ? 0 : 5 + frame[2];  // address, function, byte count, data, CRC
    case 0x06:
    case 0x10:
      return 8;  // address, function, address or value (4 bytes), CRC
    default:
      return -1;
  }
}

}  // namespace

std::uint16_t rtu_crc16(const std::uint8_t* data, int len) noexcept {
  std::uint16_t crc = 0xFFFF;
  for (int i = 0; i < len; ++i) {
    crc ^= data[i];
    for (int bit = 0; bit < 8; ++bit) {
      crc = (crc & 1u) ? static_cast<std::uint16_t>((crc >> 1) ^ 0xA001u)
                       : static_cast<std::uint16_t>(crc >> 1);
    }
  }
  return crc;
}

std::int64_t rtu_silence_ns(std::int64_t char_ns, int baud) noexcept {
  return baud > 19200 ? 1'750'000 : char_ns * 7 / 2;
}

RtuTransaction::~RtuTransaction() {
  if (epoll_fd_ >= 0) ::close(epoll_fd_);
}

bool RtuTransaction::attach(int fd) noexcept {
  if (epoll_fd_ >= 0) ::close(epoll_fd_);
  fd_ = fd;
  epoll_fd_ = epoll_create1(EPOLL_CLOEXEC);
  if (epoll_fd_ < 0) return false;
  epoll_event ev{};
  ev.events = EPOLLIN | EPOLLET;
  ev.data.fd = fd;
  if (epoll_ctl(epoll_fd_, EPOLL_CTL_ADD, fd, &ev) != 0) return false;
  // Whatever the port held before is discarded, and a reply to the previous connection's last
  // request may still be on its way: the first request, too, waits for the line's silence.
  unread_ = true;
  line_busy_until_ns_ = clock::monotonic_ns();
  return true;
}

int RtuTransaction::wait_bytes(std::int64_t deadline_ns) noexcept {
  if (unread_) return 1;
  for (;;) {
    const std::int64_t left = std::max<std::int64_t>(0, deadline_ns - clock::monotonic_ns());
    const timespec ts = clock::to_timespec(left);
    epoll_event ev{};
    const int rc = epoll_pwait2(epoll_fd_, &ev, 1, &ts, nullptr);
    if (rc > 0) {
      hung_up_ = (ev.events & (EPOLLHUP | EPOLLERR)) != 0;
      return 1;
    }
    if (rc == 0 && left == 0) return 0;
    if (rc < 0 && errno != EINTR) return -errno;
  }
}

int RtuTransaction::read_bytes(std::uint8_t* buf, std::size_t size) noexcept {
  const ssize_t n = ::read(fd_, buf, size);
  unread_ = n > 0 && static_cast<std::size_t>(n) == size;
  if (n > 0) return static_cast<int>(n);
  if (n < 0 && errno != EAGAIN && errno != EINTR) return -errno;
  // Nothing to read: a tty without bytes reads 0, a socket at its end too.
  return hung_up_ ? -EIO : 0;
}

int RtuTransaction::await_silence(std::int64_t deadline_ns) noexcept {
  // A tty holds at most 4 KiB: one read takes whatever came.
  std::array<std::uint8_t, 4096> stale{};
  bool discarded = false;
  for (;;) {
    const std::int64_t quiet_at = line_busy_until_ns_ + silence_ns_;
    if (quiet_at > deadline_ns) return EBUSY;
    // Up to the silence's end; at once, without waiting, when it has passed already.
    const int ready = wait_bytes(std::max(quiet_at, clock::monotonic_ns()));
    if (ready < 0) return -ready;
    if (ready == 0) break;
    const int n = read_bytes(stale.data(), stale.size());
    if (n < 0) return -n;
    if (n > 0) {
      // Bytes seen only now may have come earlier: the line counts as busy until now.
      discarded = true;
      line_busy_until_ns_ = clock::monotonic_ns();
    }
  }
  if (discarded) ++late_;
  return 0;
}

int RtuTransaction::send_frame(int unit, const std::uint8_t* pdu, int pdu_len) noexcept {
  std::array<std::uint8_t, kMaxFrame> frame{};
  frame[0] = static_cast<std::uint8_t>(unit);
  std::memcpy(frame.data() + 1, pdu, static_cast<std::size_t>(pdu_len));
  const std::uint16_t crc = rtu_crc16(frame.data(), pdu_len + 1);
  frame[pdu_len + 1] = static_cast<std::uint8_t>(crc & 0xFF);
  frame[pdu_len + 2] = static_cast<std::uint8_t>(crc >> 8);
  const int total = pdu_len + 3;
  request_chars_ = total;
  sent_ns_ = clock::monotonic_ns();
  if (const int err = send_frame_bytes(fd_, frame.data(), total, false); err != 0) return err;
  // The port sends the frame from now on: the line carries it for total characters.
  line_busy_until_ns_ = sent_ns_ + total * char_ns_;
  return 0;
}

void RtuTransaction::discard_unsent_request() noexcept {
  // What the port has not sent of an unanswered request would be answered into this one's wait.
  tcflush(fd_, TCOFLUSH);
  unanswered_ = false;
  // What the flush could no longer reach may have left as late as the flush's end (a pty's tty
  // worker, preempted while it held the port's buffer, delivers it and only then lets the flush
  // run): the next request keeps the silence after that request's wire time, or the two reach
  // the line as one frame.
  line_busy_until_ns_ =
      std::max(line_busy_until_ns_, clock::monotonic_ns() + request_chars_ * char_ns_);
}

int RtuTransaction::judge_frame(int unit, int function) noexcept {
  if (rx_[0] != unit) return EMBBADSLAVE;
  const int need = expected_frame_length(rx_.data(), rx_len_);
  // A byte count of 252-255 announces a frame longer than RTU allows: it would never complete.
  if (need < 0 || need > kMaxFrame) return EMBBADDATA;
  if (need == 0 || rx_len_ < need) return 0;
  const std::uint16_t crc = rtu_crc16(rx_.data(), need - 2);
  if (rx_[need - 2] != (crc & 0xFF) || rx_[need - 1] != (crc >> 8)) return EMBBADCRC;
  if ((rx_[1] & 0x7F) == function) {
    rx_len_ = need;
    return 1;
  }
  // An intact reply to another function: the previous request's, come after its timeout (a
  // command's echo while a read waits, or a read's registers while a command waits).
  ++late_;
  std::memmove(rx_.data(), rx_.data() + need, static_cast<std::size_t>(rx_len_ - need));
  rx_len_ -= need;
  return 2;
}

int RtuTransaction::receive_frame(int unit, int function, std::int64_t first_byte_by_ns,
                                  std::int64_t byte_gap_ns, std::int64_t not_after_ns) noexcept {
  rx_len_ = 0;
  std::int64_t deadline_ns = std::min(first_byte_by_ns, not_after_ns);
  for (;;) {
    const int ready = wait_bytes(deadline_ns);
    if (ready == 0) return ETIMEDOUT;
    if (ready < 0) return -ready;
    const int n = read_bytes(rx_.data() + rx_len_, rx_.size() - static_cast<std::size_t>(rx_len_));
    if (n < 0) return -n;
    if (n == 0) continue;
    rx_len_ += n;
    const std::int64_t now = clock::monotonic_ns();
    line_busy_until_ns_ = std::max(line_busy_until_ns_, now);
    // A reply that has begun may finish, as libmodbus's (mbpoll's) byte timeout lets it: the
    // timeout bounds the wait for its first byte, then each pause between its bytes, and the
    // cycle's budget bounds all of it.
    deadline_ns = std::min(now + byte_gap_ns, not_after_ns);
    // Frames that are not the answer are refused at once; the rest of such a frame is discarded
    // while the silence before the next request is awaited.
    int verdict = 2;
    while (verdict == 2 && rx_len_ > 0) verdict = judge_frame(unit, function);
    if (verdict == 1) {
      received_ns_ = now;
      return 0;
    }
    if (verdict != 0 && verdict != 2) return verdict;
  }
}

int RtuTransaction::transact(int unit, const std::uint8_t* pdu, int pdu_len, Pdu& reply,
                             int& reply_len, double timeout_s, std::int64_t not_after_ns) noexcept {
  if (epoll_fd_ < 0) return EBADF;
  if (pdu_len < 1 || pdu_len > kMaxPdu) return EINVAL;
  const auto timeout_ns = static_cast<std::int64_t>(timeout_s * 1e9);
  sent_ns_ = received_ns_ = 0;
  if (unanswered_) discard_unsent_request();
  const std::int64_t silent_by = std::min(clock::monotonic_ns() + timeout_ns, not_after_ns);
  if (const int err = await_silence(silent_by); err != 0) return err;
  if (const int err = send_frame(unit, pdu, pdu_len); err != 0) {
    // Part of it may wait in the port (EAGAIN while the tty held output back): flushed before
    // the next request, or it would go out glued to it.
    unanswered_ = true;
    return err;
  }
  if (const int err = receive_frame(unit, pdu[0], sent_ns_ + timeout_ns, timeout_ns, not_after_ns);
      err != 0) {
    unanswered_ = true;
    return err;
  }
  reply_len = rx_len_ - 3;  // without the address and the CRC
  std::memcpy(reply.data(), rx_.data() + 1, static_cast<std::size_t>(reply_len));
  return 0;
}

}  // namespace scp::drivers::modbus

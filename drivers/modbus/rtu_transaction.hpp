#pragma once
// One Modbus RTU transaction on an open serial port, timed by the clock and the line.
//
// Why not libmodbus's own RTU calls (docs/driver-modbus.md, "RTU timing", has the measurements):
// - They send a request as soon as they are called, so a command written right after a read's
//   reply follows it without the silence the Modbus serial line specification (V1.02, §2.5.1.1)
//   requires between frames; a slave that delimits frames by that silence may take both for one.
// - A flush before each request (modbus_flush: tcflush TCIOFLUSH) discards only the part of a
//   late reply that has arrived; the rest lands in the next transaction's wait and fails that one
//   too, so every late reply cost two transactions.
// - Their timeout counts only the time spent in select(); and select() (like poll() and read())
//   on a tty with no byte ready waits for the kernel's tty worker to finish delivering the bytes
//   in flight. That worker runs at ordinary priority: on a loaded machine the loop thread, at
//   real-time priority, waited behind it for milliseconds, beyond any timeout.
// - Without any flush, a request the port did not send in time still goes out later: on a loaded
//   machine the tty layer held a pty's output for many cycles, and their requests then left at
//   once, each answered into a later transaction's wait. So after a request that got no answer,
//   the port's unsent output is discarded (tcflush TCOFLUSH) before the next one, and the next
//   one waits for the silence as if the request had left when the flush returned (what the flush
//   could not reach may have left as late as that).
// Here a transaction is: wait until the line has been silent for t3.5 (discarding whatever
// arrives meanwhile: the rest of a late reply), send the request, collect the reply until its
// length (known from its function code and byte count) is complete, check its CRC and unit. One
// deadline read from CLOCK_MONOTONIC bounds all of it. The waits are on an edge-triggered epoll
// instance, which sleeps without asking the tty whether it has bytes (the question that waits
// for the worker), and the port is read only when epoll reported bytes. No allocation, no lock:
// the loop thread calls it.

#include <array>
#include <cstdint>
#include <limits>

#include "drivers/modbus/pdu.hpp"

namespace scp::drivers::modbus {

class RtuTransaction {
 public:
  // Largest RTU frame: address + PDU + CRC.
  static constexpr int kMaxFrame = 1 + kMaxPdu + 2;

  // `char_ns`: one character on the line; `silence_ns`: the inter-frame silence kept before
  // every request (t3.5: rtu_silence_ns()).
  RtuTransaction(std::int64_t char_ns = 0, std::int64_t silence_ns = 0) noexcept
      : char_ns_(char_ns), silence_ns_(silence_ns) {}
  ~RtuTransaction();
  RtuTransaction(const RtuTransaction&) = delete;
  RtuTransaction& operator=(const RtuTransaction&) = delete;

  // The open, non-blocking serial port (or any byte stream) the transactions use; it stays the
  // caller's to close. False, with errno, if it cannot be watched. Not for the loop thread.
  bool attach(int fd) noexcept;

  // Sends `pdu` (function code and data) to `unit` on the attached port and collects its reply. The
  // silence before the request is awaited for at most `timeout_s`, the reply's first byte for at
  // most `timeout_s` after the request left and each later byte for at most `timeout_s` after
  // the one before (libmodbus's response and byte timeouts), and none past `not_after_ns`
  // (CLOCK_MONOTONIC: the caller's budget for a cycle of transactions). Returns 0 with the reply's
  // PDU in `reply` (its length in `reply_len`), or an errno-style code: ETIMEDOUT (no whole reply
  // in time), EBUSY (the line never fell silent: bytes kept arriving), EMBBADCRC, EMBBADSLAVE (a
  // reply from another unit), EMBBADDATA (a reply that is no answer to this request), or the errno
  // of read/write. Exception replies are returned as replies. A whole, intact reply to another
  // function (the previous request's, come late) is discarded and counted, and the wait goes on.
  int transact(int unit, const std::uint8_t* pdu, int pdu_len, Pdu& reply, int& reply_len,
               double timeout_s,
               std::int64_t not_after_ns = std::numeric_limits<std::int64_t>::max()) noexcept;

  // CLOCK_MONOTONIC ns when the last transaction's request was handed to the port (after the
  // silence), and when its whole reply had been read; 0 when it was not sent, or no reply came.
  std::int64_t request_sent_ns() const noexcept { return sent_ns_; }
  std::int64_t reply_received_ns() const noexcept { return received_ns_; }
  // Late replies (or noise) discarded while waiting for the silence before a request.
  std::uint64_t late_replies() const noexcept { return late_; }

 private:
  // Waits until epoll reports bytes (or bytes were left unread): 1, 0 at the deadline, −errno.
  int wait_bytes(std::int64_t deadline_ns) noexcept;
  // Reads what the port holds into buf: the count (0: nothing after all), or −errno.
  int read_bytes(std::uint8_t* buf, std::size_t size) noexcept;
  // Reads and discards until the line has been silent for silence_ns_: 0, EBUSY past the
  // deadline, or an errno.
  int await_silence(std::int64_t deadline_ns) noexcept;
  int send_frame(int unit, const std::uint8_t* pdu, int pdu_len) noexcept;
  // Discards the port's unsent output after a request that got no answer.
  void discard_unsent_request() noexcept;
  // Collects the reply: its first byte by `first_byte_by_ns`, each later one within
  // `byte_gap_ns` of the one before, all of it by `not_after_ns`.
  int receive_frame(int unit, int function, std::int64_t first_byte_by_ns, std::int64_t byte_gap_ns,
                    std::int64_t not_after_ns) noexcept;
  // Judges the bytes received so far: 1 = our whole reply (rx_len_ cut to it), 0 = more bytes
  // needed, 2 = a late reply to another function was dropped, or an errno-style code.
  int judge_frame(int unit, int function) noexcept;

  std::int64_t char_ns_;
  std::int64_t silence_ns_;
  int fd_ = -1;
  int epoll_fd_ = -1;
  // A read filled its buffer: more bytes may wait, and edge-triggered epoll will not say so.
  bool unread_ = false;
  bool hung_up_ = false;
  // The last request went out and got no whole reply: some of it may still wait in the port.
  bool unanswered_ = false;
  // The last request's length in characters.
  int request_chars_ = 0;
  std::array<std::uint8_t, kMaxFrame> rx_{};
  int rx_len_ = 0;
  // The line's last activity: the end of the last byte read, or of the last request's wire time.
  std::int64_t line_busy_until_ns_ = 0;
  std::int64_t sent_ns_ = 0;
  std::int64_t received_ns_ = 0;
  std::uint64_t late_ = 0;
};

// The Modbus RTU CRC-16 of `len` bytes (polynomial 0xA001 reflected, initial 0xFFFF); sent low
// byte first.
std::uint16_t rtu_crc16(const std::uint8_t* data, int len) noexcept;

// t3.5 (Modbus over serial line V1.02, §2.5.1.1): 3.5 characters, fixed at 1.75 ms above
// 19200 Bd, where the character time would make it impractically short for a slave's timer.
std::int64_t rtu_silence_ns(std::int64_t char_ns, int baud) noexcept;

}  // namespace scp::drivers::modbus

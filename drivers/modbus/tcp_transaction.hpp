#pragma once
// One Modbus TCP transaction on a connected socket, with late replies recognised by their
// transaction id and discarded.
//
// libmodbus takes whatever reply comes next as the answer to the request in flight: a reply that
// arrives after its timeout (and after the flush) makes the next transaction fail with a
// transaction-id mismatch, and every later one read its predecessor's reply. Here the bytes of a
// connection are kept between transactions, each frame is matched by its transaction id, and a
// frame with an earlier id is counted and dropped while the wait for the right one continues.
// No allocation, no lock: the loop thread calls it.

#include <array>
#include <cstdint>
#include <limits>

#include "drivers/modbus/pdu.hpp"

namespace scp::drivers::modbus {

class TcpTransaction {
 public:
  // Largest Modbus TCP frame: 7-byte MBAP header + 253-byte PDU.
  static constexpr int kMaxFrame = 260;
  static constexpr int kMaxPdu = modbus::kMaxPdu;

  // A new connection: forget bytes buffered from the old one.
  void reset() noexcept {
    rx_len_ = 0;
    last_recv_ns_ = reply_ns_ = sent_ns_ = 0;
  }

  // Sends `pdu` (function code and data) to `unit` on `fd` and waits at most `timeout_s`, and
  // not past `not_after_ns` (CLOCK_MONOTONIC: the caller's budget for a cycle of transactions),
  // for the reply carrying the same transaction id. Returns 0 with the reply's PDU in `reply`
  // (its length in `reply_len`), or an errno-style code: ETIMEDOUT (no reply in time), EMBBADDATA
  // (bytes that are no Modbus TCP frame, or a reply from another unit: the stream cannot be
  // trusted), ECONNRESET (the peer closed), or the errno of send/recv. Exception replies are
  // returned as replies; the caller decodes them.
  int transact(int fd, int unit, const std::uint8_t* pdu, int pdu_len,
               std::array<std::uint8_t, kMaxPdu>& reply, int& reply_len, double timeout_s,
               std::int64_t not_after_ns = std::numeric_limits<std::int64_t>::max()) noexcept;

  // Replies that arrived after their transaction had given up on them.
  std::uint64_t late_replies() const noexcept { return late_; }

  // CLOCK_MONOTONIC ns at which the kernel received the bytes that completed the last reply
  // transact() returned (0 when the socket gave no time stamp: enable_receive_stamps() failed or
  // was not called). On a loaded machine the loop thread may run milliseconds after its reply
  // arrived; the kernel stamps the segment when it arrives (on loopback: when the peer sent it),
  // so the transaction's end is not moved by the thread's own wake-up latency (issue 9).
  std::int64_t reply_received_ns() const noexcept { return reply_ns_; }
  // CLOCK_MONOTONIC ns just before the last transaction's request was sent.
  std::int64_t request_sent_ns() const noexcept { return sent_ns_; }

 private:
  int send_frame(int fd, int unit, std::uint16_t tid, const std::uint8_t* pdu,
                 int pdu_len) noexcept;
  // Reads what the socket holds, with the kernel's receive stamp: 0 or an errno-style code.
  int receive(int fd) noexcept;
  // Takes one whole frame off the buffer if there is one: 1 = frame, 0 = need more bytes,
  // -1 = garbage.
  int take_frame(std::uint16_t& tid, int& unit, std::array<std::uint8_t, kMaxPdu>& pdu,
                 int& pdu_len) noexcept;

  std::array<std::uint8_t, 2 * kMaxFrame> rx_{};
  int rx_len_ = 0;
  std::uint16_t next_tid_ = 1;
  std::uint64_t late_ = 0;
  std::int64_t last_recv_ns_ = 0;  // kernel stamp of the latest bytes read, 0 if none
  std::int64_t reply_ns_ = 0;
  std::int64_t sent_ns_ = 0;
};

// Asks the kernel to stamp every segment `fd` receives (SO_TIMESTAMPNS). False if it refused:
// TcpTransaction then reports no reception times and the driver uses its own clock.
bool enable_receive_stamps(int fd) noexcept;

}  // namespace scp::drivers::modbus

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

namespace scp::drivers::modbus {

class TcpTransaction {
 public:
  // Largest Modbus TCP frame: 7-byte MBAP header + 253-byte PDU.
  static constexpr int kMaxFrame = 260;
  static constexpr int kMaxPdu = 253;

  // A new connection: forget bytes buffered from the old one.
  void reset() noexcept {
    rx_len_ = 0;
    last_recv_ns_ = reply_ns_ = 0;
  }

  // Sends `pdu` (function code and data) to `unit` on `fd` and waits at most `timeout_s` for the
  // reply carrying the same transaction id. Returns 0 with the reply's PDU in `reply` (its
  // length in `reply_len`), or an errno-style code: ETIMEDOUT (no reply in time), EMBBADDATA
  // (bytes that are no Modbus TCP frame, or a reply from another unit: the stream cannot be
  // trusted), ECONNRESET (the peer closed), or the errno of send/recv. Exception replies are
  // returned as replies; the caller decodes them.
  int transact(int fd, int unit, const std::uint8_t* pdu, int pdu_len,
               std::array<std::uint8_t, kMaxPdu>& reply, int& reply_len, double timeout_s) noexcept;

  // Replies that arrived after their transaction had given up on them.
  std::uint64_t late_replies() const noexcept { return late_; }

  // CLOCK_MONOTONIC ns at which the kernel received the bytes that completed the last reply
  // transact() returned (0 when the socket gave no time stamp: enable_receive_stamps() failed or
  // was not called). On a loaded machine the loop thread may run milliseconds after its reply
  // arrived; the kernel stamps the segment when it arrives (on loopback: when the peer sent it),
  // so the transaction's end is not moved by the thread's own wake-up latency (issue 9).
  std::int64_t reply_received_ns() const noexcept { return reply_ns_; }

 private:
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
};

// Asks the kernel to stamp every segment `fd` receives (SO_TIMESTAMPNS). False if it refused:
// TcpTransaction then reports no reception times and the driver uses its own clock.
bool enable_receive_stamps(int fd) noexcept;

// Protocol data units of the requests the driver sends, and the checks of their replies. Each
// check returns 0, MODBUS_ENOBASE + exception code for an exception reply, or EMBBADDATA.
int read_registers_pdu(bool input_table, int address, int count, std::uint8_t* pdu) noexcept;
int check_read_reply(bool input_table, int count, const std::uint8_t* reply, int reply_len,
                     std::uint16_t* registers) noexcept;
// Function 6 (one register) or 16 (`count` registers).
int write_registers_pdu(int function, int address, int count, const std::uint16_t* values,
                        std::uint8_t* pdu) noexcept;
int check_write_reply(const std::uint8_t* request, int request_len, const std::uint8_t* reply,
                      int reply_len) noexcept;

}  // namespace scp::drivers::modbus

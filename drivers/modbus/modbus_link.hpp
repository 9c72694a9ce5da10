#pragma once
// One connection to the DAQ: the libmodbus context that opened it (TCP socket or configured
// serial port) and the state of its transactions, owned together and closed together.
//
// Every Modbus transaction of the driver goes through transact(): request PDU → the transport's
// framing and wait (tcp_transaction.hpp, rtu_transaction.hpp) → reply PDU; read_registers() and
// write_registers() add the request's encoding and the reply's check (pdu.hpp). libmodbus opens
// and configures the port; its own request calls are not used (rtu_transaction.hpp says why).
//
// Threads: a link is used by one thread at a time. The reconnect thread creates links and
// destroys retired ones; the loop thread only uses them (no allocation, no lock, no free).

#include <cstdint>
#include <limits>
#include <memory>
#include <string>

#include "drivers/modbus/modbus_settings.hpp"
#include "drivers/modbus/pdu.hpp"
#include "drivers/modbus/read_plan.hpp"
#include "drivers/modbus/rtu_transaction.hpp"
#include "drivers/modbus/tcp_transaction.hpp"

struct _modbus;  // libmodbus' modbus_t, kept out of this header

namespace scp::drivers::modbus {

class ModbusLink {
 public:
  // Opens the connection `settings` describe. nullptr when it cannot, with `error` naming the
  // cause and the remedy, and errno kept from the failed call.
  static std::unique_ptr<ModbusLink> connect(const ModbusSettings& settings, std::string& error);
  ~ModbusLink();
  ModbusLink(const ModbusLink&) = delete;
  ModbusLink& operator=(const ModbusLink&) = delete;

  // The end of the budget the next transactions share (CLOCK_MONOTONIC ns): each waits for its
  // reply at most the response timeout, and none past this instant. The loop's cycle sets it so
  // that its transactions together never take longer than check_timing() approved.
  void limit_until(std::int64_t not_after_ns) noexcept { not_after_ns_ = not_after_ns; }

  // One transaction: 0 with the reply's PDU, or an errno-style code (those of
  // TcpTransaction::transact and RtuTransaction::transact).
  int transact(const std::uint8_t* request, int request_len, Pdu& reply, int& reply_len) noexcept;
  // Reads `block` into `registers` (block.count values): 0, an exception (MODBUS_ENOBASE +
  // code) or a transport error.
  int read_registers(const ReadBlock& block, std::uint16_t* registers) noexcept;
  // Writes `count` registers from `address` with function 6 (count 1) or 16; the reply must
  // echo the request.
  int write_registers(int function, int address, int count, const std::uint16_t* values) noexcept;

  // When the last transaction's request left (after the silence RTU keeps before it) and when its
  // reply arrived (over TCP: when the kernel received it, if it says so), CLOCK_MONOTONIC ns;
  // 0 when the request was not sent or no reply came.
  std::int64_t request_sent_ns() const noexcept;
  std::int64_t reply_received_ns() const noexcept;
  // Replies that came after their transaction gave up on them, discarded.
  std::uint64_t late_replies() const noexcept;

 private:
  struct ContextFree {
    void operator()(_modbus* ctx) const noexcept;
  };
  ModbusLink(_modbus* ctx, const ModbusSettings& settings) noexcept;

  std::unique_ptr<_modbus, ContextFree> ctx_;
  int fd_ = -1;
  Transport transport_;
  int unit_;
  double timeout_s_;
  std::int64_t not_after_ns_ = std::numeric_limits<std::int64_t>::max();
  TcpTransaction tcp_;
  RtuTransaction rtu_;
};

}  // namespace scp::drivers::modbus

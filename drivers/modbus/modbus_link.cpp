#include "drivers/modbus/modbus_link.hpp"

#include <modbus/modbus.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>

#include "common/clock.hpp"
#include "drivers/modbus/wire_time.hpp"

namespace scp::drivers::modbus {

namespace {

modbus_t* new_context(const ModbusSettings& s) {
  if (s.transport == Transport::tcp) {
    // _pi resolves host names and IPv6, unlike modbus_new_tcp.
    return modbus_new_tcp_pi(s.host.c_str(), std::to_string(s.port).c_str());
  }
  return modbus_new_rtu(s.device.c_str(), s.baud, s.parity, s.data_bits, s.stop_bits);
}

std::string connect_remedy(const ModbusSettings& s, int err) {
  if (s.transport == Transport::tcp) {
    return " — check that the DAQ is powered and reachable and that driver.modbus.tcp.host/port "
           "are right";
  }
  if (err == EACCES || err == EPERM) {
    return " — add the daemon's user to the 'dialout' group (usermod -aG dialout USER, then log "
           "in again) or fix the udev rule for " +
           s.device;
  }
  if (err == ENOENT) {
    return " — no such device; check driver.modbus.rtu.device (ls /dev/ttyUSB* /dev/serial/by-id)";
  }
  return "";
}

}  // namespace

void ModbusLink::ContextFree::operator()(modbus_t* ctx) const noexcept {
  modbus_close(ctx);
  modbus_free(ctx);
}

ModbusLink::ModbusLink(modbus_t* ctx, const ModbusSettings& s) noexcept
    : ctx_(ctx),
      fd_(modbus_get_socket(ctx)),
      transport_(s.transport),
      unit_(s.unit_id),
      timeout_s_(s.response_timeout_s),
      rtu_(std::llround(char_time_s(s) * 1e9),
           s.enforce_period_budget ? rtu_silence_ns(std::llround(char_time_s(s) * 1e9), s.baud)
                                   : 0) {}

ModbusLink::~ModbusLink() = default;

std::unique_ptr<ModbusLink> ModbusLink::connect(const ModbusSettings& s, std::string& error) {
  std::unique_ptr<modbus_t, ContextFree> ctx(new_context(s));
  if (ctx == nullptr) {
    error = std::string("cannot create the libmodbus context: ") + modbus_strerror(errno);
    return nullptr;
  }
  // The TCP connect waits up to the response timeout (libmodbus); transactions bound themselves.
  const double t = s.response_timeout_s;
  const auto sec = static_cast<std::uint32_t>(t);
  const auto usec = static_cast<std::uint32_t>(std::lround((t - sec) * 1e6));
  if (modbus_set_slave(ctx.get(), s.unit_id) == -1 ||
      modbus_set_response_timeout(ctx.get(), sec, std::min<std::uint32_t>(usec, 999999)) == -1) {
    error = std::string("cannot configure the libmodbus context: ") + modbus_strerror(errno);
    return nullptr;
  }
  if (modbus_connect(ctx.get()) == -1) {
    const int err = errno;
    error = modbus_strerror(err) + connect_remedy(s, err);
    errno = err;
    return nullptr;
  }
  // Without the kernel's stamps a transaction ends at the loop thread's clock reading: worse on a
  // loaded machine, not wrong.
  if (s.transport == Transport::tcp) enable_receive_stamps(modbus_get_socket(ctx.get()));
  std::unique_ptr<ModbusLink> link(new ModbusLink(ctx.release(), s));
  if (s.transport == Transport::rtu && !link->rtu_.attach(link->fd_)) {
    error = std::string("cannot watch the serial port (epoll): ") + std::strerror(errno);
    return nullptr;
  }
  return link;
}

int ModbusLink::transact(const std::uint8_t* request, int request_len, Pdu& reply,
                         int& reply_len) noexcept {
  if (transport_ == Transport::tcp) {
    return tcp_.transact(fd_, unit_, request, request_len, reply, reply_len, timeout_s_,
                         not_after_ns_);
  }
  return rtu_.transact(unit_, request, request_len, reply, reply_len, timeout_s_, not_after_ns_);
}

int ModbusLink::read_registers(const ReadBlock& block, std::uint16_t* registers) noexcept {
  const bool input = block.table == Table::input;
  Pdu request{};
  Pdu reply{};
  int reply_len = 0;
  const int len = read_registers_pdu(input, block.address, block.count, request.data());
  const int err = transact(request.data(), len, reply, reply_len);
  return err != 0 ? err : check_read_reply(input, block.count, reply.data(), reply_len, registers);
}

int ModbusLink::write_registers(int function, int address, int count,
                                const std::uint16_t* values) noexcept {
  Pdu request{};
  Pdu reply{};
  int reply_len = 0;
  const int len = write_registers_pdu(function, address, count, values, request.data());
  const int err = transact(request.data(), len, reply, reply_len);
  return err != 0 ? err : check_write_reply(request.data(), len, reply.data(), reply_len);
}

std::int64_t ModbusLink::request_sent_ns() const noexcept {
  return transport_ == Transport::tcp ? tcp_.request_sent_ns() : rtu_.request_sent_ns();
}

std::int64_t ModbusLink::reply_received_ns() const noexcept {
  if (transport_ == Transport::rtu) return rtu_.reply_received_ns();
  // The kernel's stamp, if it is plausible: not before the request was sent (bytes buffered
  // earlier), not after now (a clock step).
  const std::int64_t received = tcp_.reply_received_ns();
  return received > tcp_.request_sent_ns() && received <= clock::monotonic_ns() ? received : 0;
}

std::uint64_t ModbusLink::late_replies() const noexcept {
  return transport_ == Transport::tcp ? tcp_.late_replies() : rtu_.late_replies();
}

}  // namespace scp::drivers::modbus

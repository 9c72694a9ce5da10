#pragma once
// Protocol data units of the requests the driver sends, and the checks of their replies: the
// part of a Modbus transaction that TCP and RTU share (each wraps it in its own framing:
// tcp_transaction.hpp, rtu_transaction.hpp).

#include <array>
#include <cstdint>

namespace scp::drivers::modbus {

// Largest PDU: function code + 252 bytes of data.
inline constexpr int kMaxPdu = 253;
using Pdu = std::array<std::uint8_t, kMaxPdu>;

// Each check returns 0, MODBUS_ENOBASE + exception code for an exception reply, or EMBBADDATA.
int read_registers_pdu(bool input_table, int address, int count, std::uint8_t* pdu) noexcept;
int check_read_reply(bool input_table, int count, const std::uint8_t* reply, int reply_len,
                     std::uint16_t* registers) noexcept;
// Function 6 (one register) or 16 (`count` registers).
int write_registers_pdu(int function, int address, int count, const std::uint16_t* values,
                        std::uint8_t* pdu) noexcept;
int check_write_reply(const std::uint8_t* request, int request_len, const std::uint8_t* reply,
                      int reply_len) noexcept;

}  // namespace scp::drivers::modbus

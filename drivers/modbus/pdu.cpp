#include "drivers/modbus/pdu.hpp"

#include <modbus/modbus.h>

#include <cstring>

namespace scp::drivers::modbus {

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

#pragma once
// When a Modbus transaction's event happens inside it: the instant the slave samples its inputs
// (a read) or applies the command (a write), relative to the midpoint of the transaction as the
// master sees it (request sent ... reply received).
//
// Model (Modbus over serial line V1.02, §2.5.1): a character is 1 start + data + parity + stop
// bits; the slave acts once the request's last character has arrived and the line has been silent
// for t3.5 (3.5 characters), then sends its reply. With a request of R characters and a reply of
// Q, the master's transaction lasts R + 3.5 + Q characters and the event comes R + 3.5 after its
// start: (R + 3.5 − Q)/2 characters after the midpoint. A read's reply is long (the registers),
// so its sample comes before the midpoint; a write's request is the long one, so its command
// lands after it. Over TCP the frames take microseconds: the midpoint.
// What the model cannot know (a slave's own turnaround, its ADC's age, its DAC's update cycle) is
// the configured driver.modbus.timing.input_latency / output_latency (docs/driver-modbus.md).

#include "drivers/modbus/modbus_settings.hpp"
#include "drivers/modbus/register_codec.hpp"

namespace scp::drivers::modbus {

inline constexpr double kRtuFrameGapChars = 3.5;

// Seconds one character takes on the line (0 over TCP, unless a gateway puts a serial line behind
// it: LinkTiming::serial_line).
inline double char_time_s(const ModbusSettings& s) noexcept {
  const bool line = s.transport == Transport::rtu || s.timing.serial_line;
  if (!line || s.baud <= 0) return 0.0;
  const int bits = 1 + s.data_bits + (s.parity == 'N' ? 0 : 1) + s.stop_bits;
  return static_cast<double>(bits) / static_cast<double>(s.baud);
}

// RTU frame lengths in characters: address, function, data, CRC.
inline int read_request_chars() noexcept {
  return 8;
}  // addr fc start(2) count(2) crc(2)
inline int read_reply_chars(int registers) noexcept {
  return 5 + 2 * registers;
}
inline int write_request_chars(int registers) noexcept {
  return registers == 1 ? 8 : 9 + 2 * registers;  // function 6, or 16 with its byte count
}
inline int write_reply_chars() noexcept {
  return 8;
}

// Seconds from the transaction's midpoint to its event (negative: before the midpoint).
inline double event_after_midpoint_s(const ModbusSettings& s, int request_chars,
                                     int reply_chars) noexcept {
  const double c = char_time_s(s);
  if (c == 0.0) return 0.0;
  return 0.5 * (request_chars + kRtuFrameGapChars - reply_chars) * c;
}

}  // namespace scp::drivers::modbus

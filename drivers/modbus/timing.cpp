#include "drivers/modbus/timing.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <sstream>
#include <string>
#include <vector>

#include "drivers/driver.hpp"
#include "drivers/modbus/read_plan.hpp"
#include "drivers/modbus/register_codec.hpp"
#include "drivers/modbus/rtu_transaction.hpp"
#include "drivers/modbus/wire_time.hpp"

namespace scp::drivers::modbus {

namespace {

std::string ms(double seconds) {
  std::ostringstream out;
  out.precision(3);
  out << seconds * 1e3 << " ms";
  return out.str();
}

std::string line_name(const ModbusSettings& s) {
  return std::to_string(s.baud) + " Bd " + std::to_string(s.data_bits) + s.parity +
         std::to_string(s.stop_bits);
}

void refuse_budget(const ModbusSettings& settings, int n, double period_s) {
  const double worst = settings.response_timeout_s * n;
  std::ostringstream out;
  out.precision(4);
  out << "modbus: response timeout " << settings.response_timeout_s * 1e3 << " ms x " << n
      << " transactions per cycle = " << worst * 1e3 << " ms exceeds the " << period_s * 1e3
      << " ms loop period; raise loop.period_s to at least " << worst * 1e3
      << " ms, or lower driver.modbus.response_timeout to at most " << period_s / n * 1e3 << " ms";
  if (n > 2) out << ", or place the signals in adjacent registers so they are read in one request";
  throw DriverError(out.str());
}

}  // namespace

int transactions_per_cycle(const ModbusSettings& settings) {
  // + the command write, + the watchdog heartbeat in the cycles that carry one.
  return static_cast<int>(plan_reads(settings, settings.max_read_gap).blocks.size()) + 1 +
         (settings.watchdog_register >= 0 ? 1 : 0);
}

LineCycle line_cycle(const ModbusSettings& settings) {
  LineCycle out;
  out.transactions = transactions_per_cycle(settings);
  const double c = settings.transport == Transport::rtu ? char_time_s(settings) : 0.0;
  if (c == 0.0) return out;
  auto add = [&](int request_chars, int reply_chars) {
    const double exchange = (request_chars + reply_chars) * c;
    out.wire_s += exchange;
    out.longest_exchange_s = std::max(out.longest_exchange_s, exchange);
    out.longest_first_byte_s = std::max(out.longest_first_byte_s, (request_chars + 1) * c);
  };
  for (const ReadBlock& block : plan_reads(settings, settings.max_read_gap).blocks)
    add(read_request_chars(), read_reply_chars(block.count));
  add(write_request_chars(register_count(settings.command.type)), write_reply_chars());
  if (settings.watchdog_register >= 0) add(write_request_chars(1), write_reply_chars());
  const auto char_ns = static_cast<std::int64_t>(std::llround(c * 1e9));
  out.silences_s =
      out.transactions * static_cast<double>(rtu_silence_ns(char_ns, settings.baud)) * 1e-9;
  return out;
}

void check_timing(const ModbusSettings& settings, double period_s) {
  if (!std::isfinite(period_s) || period_s <= 0.0) {
    throw DriverError("modbus: the loop period must be a positive number of seconds");
  }
  const int n = transactions_per_cycle(settings);
  if (settings.response_timeout_s * n > period_s) refuse_budget(settings, n, period_s);
}

std::vector<std::string> line_timing_warnings(const ModbusSettings& settings, double period_s) {
  std::vector<std::string> out;
  const LineCycle line = line_cycle(settings);
  if (line.wire_s == 0.0) return out;
  const double timeout = settings.response_timeout_s;
  if (timeout < line.longest_first_byte_s) {
    out.push_back(ms(timeout) + " is shorter than the " + ms(line.longest_first_byte_s) +
                  " the longest request and its reply's first character take at " +
                  line_name(settings) +
                  ": on a real line no reply can begin in time (a pty without wire time is "
                  "faster); raise the timeout (the slave's turnaround on top), raise "
                  "driver.modbus.rtu.baud or write fewer registers at once");
  }
  const double cycle = line.wire_s + line.silences_s;
  if (cycle > period_s) {
    out.push_back("one cycle's " + std::to_string(line.transactions) + " transactions take " +
                  ms(cycle) + " on the line at " + line_name(settings) + " (" + ms(line.wire_s) +
                  " of frames, " + ms(line.silences_s) +
                  " of t3.5 silences) before any turnaround, more than the " + ms(period_s) +
                  " loop period; raise loop.period_s or driver.modbus.rtu.baud, or read fewer "
                  "registers");
  }
  const double worst = line.transactions * timeout + line.silences_s;
  if (worst > period_s && cycle <= period_s) {
    out.push_back(std::to_string(line.transactions) + " transactions x " + ms(timeout) +
                  " + their t3.5 silences (" + ms(line.silences_s) + ") = " + ms(worst) +
                  " exceed the " + ms(period_s) +
                  " loop period: a transaction that waits its whole timeout leaves the next less "
                  "than its timeout; lower the timeout to " +
                  ms((period_s - line.silences_s) / line.transactions) + " or raise loop.period_s");
  }
  return out;
}

}  // namespace scp::drivers::modbus

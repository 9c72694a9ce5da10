#include "drivers/modbus/modbus_driver.hpp"

#include <modbus/modbus.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <ctime>
#include <utility>

#include "drivers/modbus/register_codec.hpp"
#include "drivers/modbus/timing.hpp"
#include "drivers/modbus/wire_time.hpp"

namespace scp::drivers::modbus {

namespace {

constexpr const char* kLinkDown = "modbus: link down, reconnecting";
constexpr const char* kNotFinite = "modbus: non-finite voltage command refused, 0 V written";
constexpr const char* kOutOfRange =
    "modbus: voltage command outside driver.modbus.command.min/max refused, 0 V written";
constexpr const char* kNotEncodable =
    "modbus: voltage command not representable in driver.modbus.command.type";

const char* exception_name(int code) {
  switch (code) {
    case 1:
      return "illegal function: the device does not support this function code";
    case 2:
      return "illegal data address: the register is not in the device's map";
    case 3:
      return "illegal data value";
    case 4:
      return "server device failure";
    case 5:
      return "acknowledge (device busy with a long command)";
    case 6:
      return "server device busy";
    case 7:
      return "negative acknowledge";
    case 8:
      return "memory parity error";
    case 10:
      return "gateway path unavailable";
    case 11:
      return "gateway target device failed to respond";
    default:
      return "unknown exception";
  }
}

std::string range_text(int first, int count) {
  return count == 1 ? std::to_string(first)
                    : std::to_string(first) + "-" + std::to_string(first + count - 1);
}

std::int64_t monotonic_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

bool is_link_error(int err) {
  switch (err) {
    case ECONNRESET:
    case EPIPE:
    case EBADF:
    case ENOTCONN:
    case ECONNREFUSED:
    case ECONNABORTED:
    case EIO:  // a USB-serial adapter unplugged
    case ENXIO:
    case ENODEV:
      return true;
    default:
      return false;
  }
}

}  // namespace

ModbusDriver::ModbusDriver(ModbusSettings settings, double period_s)
    : settings_(std::move(settings)), period_s_(period_s) {
  // Nothing acknowledged before open(): a status published before it must not say "confirmed".
  stats_.output_confirmed = false;
  stats_.link_up = false;
}

ModbusDriver::~ModbusDriver() {
  close();
}

ModbusDriver::Reasons ModbusDriver::make_reasons(const std::string& what, int max_failures) {
  Reasons r;
  r.why[kOther] = what + ": invalid reply";
  for (int code = 1; code <= 11; ++code) {
    r.why[static_cast<std::size_t>(code)] =
        what + ": exception " + std::to_string(code) + " (" + exception_name(code) + ")";
  }
  r.why[kTimeout] = what + ": no reply within driver.modbus.response_timeout";
  r.why[kLinkLost] = what + ": connection lost";
  r.why[kCrc] = what + ": CRC error in the reply (noise on the line, or wrong baud/parity)";
  r.why[kBadData] = what + ": invalid reply (wrong length, function code or frame)";
  r.why[kBadSlave] = what + ": reply from another unit id (check driver.modbus.unit_id)";
  for (std::size_t i = 0; i < kReasonCount; ++i) {
    r.dropped[i] = r.why[i] + "; link dropped, reconnecting";
  }
  r.dropped[kTimeout] = what + ": no reply to " + std::to_string(max_failures + 1) +
                        " transactions in a row (driver.modbus.max_consecutive_failures); link "
                        "dropped, reconnecting";
  return r;
}

std::size_t ModbusDriver::reason_index(int err) noexcept {
  if (err > MODBUS_ENOBASE && err <= EMBXGTAR)
    return static_cast<std::size_t>(err - MODBUS_ENOBASE);
  if (err == ETIMEDOUT) return kTimeout;
  if (err == EMBBADCRC) return kCrc;
  if (err == EMBBADDATA || err == EMBMDATA || err == EMBBADEXC || err == EMBUNKEXC) return kBadData;
  if (err == EMBBADSLAVE) return kBadSlave;
  if (is_link_error(err)) return kLinkLost;
  return kOther;
}

std::string ModbusDriver::endpoint() const {
  if (settings_.transport == Transport::tcp) {
    return "tcp " + settings_.host + ":" + std::to_string(settings_.port) + " unit " +
           std::to_string(settings_.unit_id);
  }
  return "rtu " + settings_.device + " " + std::to_string(settings_.baud) + " " + settings_.parity +
         std::to_string(settings_.data_bits) + std::to_string(settings_.stop_bits) + " unit " +
         std::to_string(settings_.unit_id);
}

int ModbusDriver::write_function() const noexcept {
  if (settings_.command.function != 0) return settings_.command.function;
  return register_count(settings_.command.type) == 1 ? 6 : 16;
}

modbus_t* ModbusDriver::make_context(std::string& error) const {
  modbus_t* ctx = nullptr;
  if (settings_.transport == Transport::tcp) {
    // _pi resolves host names and IPv6, unlike modbus_new_tcp.
    ctx = modbus_new_tcp_pi(settings_.host.c_str(), std::to_string(settings_.port).c_str());
  } else {
    ctx = modbus_new_rtu(settings_.device.c_str(), settings_.baud, settings_.parity,
                         settings_.data_bits, settings_.stop_bits);
  }
  if (ctx == nullptr) {
    error = std::string("cannot create the libmodbus context: ") + modbus_strerror(errno);
    return nullptr;
  }
  const double t = settings_.response_timeout_s;
  const auto sec = static_cast<std::uint32_t>(t);
  const auto usec = static_cast<std::uint32_t>(std::lround((t - sec) * 1e6));
  // Byte timeout 0 disables it, so the response timeout bounds the whole reply: a trickling
  // device cannot stretch one transaction beyond the budget check_timing() approved.
  if (modbus_set_slave(ctx, settings_.unit_id) == -1 ||
      modbus_set_response_timeout(ctx, sec, std::min<std::uint32_t>(usec, 999999)) == -1 ||
      modbus_set_byte_timeout(ctx, 0, 0) == -1 ||
      modbus_set_error_recovery(ctx, MODBUS_ERROR_RECOVERY_NONE) == -1) {
    error = std::string("cannot configure the libmodbus context: ") + modbus_strerror(errno);
    modbus_free(ctx);
    return nullptr;
  }
  if (modbus_connect(ctx) == -1) {
    const int err = errno;
    error = modbus_strerror(err);
    if (settings_.transport == Transport::rtu && (err == EACCES || err == EPERM)) {
      error +=
          " — add the daemon's user to the 'dialout' group (usermod -aG dialout USER, then "
          "log in again) or fix the udev rule for " +
          settings_.device;
    } else if (settings_.transport == Transport::rtu && err == ENOENT) {
      error +=
          " — no such device; check driver.modbus.rtu.device (ls /dev/ttyUSB* /dev/serial/by-id)";
    } else if (settings_.transport == Transport::tcp) {
      error +=
          " — check that the DAQ is powered and reachable and that driver.modbus.tcp.host/port "
          "are right";
    }
    errno = err;
    modbus_free(ctx);
    return nullptr;
  }
  // Without the kernel's stamps the transactions' ends are the loop thread's clock readings
  // (see transaction_end_ns): worse on a loaded machine, not wrong.
  if (settings_.transport == Transport::tcp) enable_receive_stamps(modbus_get_socket(ctx));
  return ctx;
}

int ModbusDriver::read_block(modbus_t* ctx, TcpTransaction& tcp, const ReadBlock& b,
                             std::uint16_t* regs) const noexcept {
  const bool input = b.table == Table::input;
  if (settings_.transport == Transport::tcp) {
    std::array<std::uint8_t, TcpTransaction::kMaxPdu> request{};
    std::array<std::uint8_t, TcpTransaction::kMaxPdu> reply{};
    int reply_len = 0;
    const int n = read_registers_pdu(input, b.address, b.count, request.data());
    const int rc = tcp.transact(modbus_get_socket(ctx), settings_.unit_id, request.data(), n, reply,
                                reply_len, settings_.response_timeout_s);
    if (rc != 0) return rc;
    return check_read_reply(input, b.count, reply.data(), reply_len, regs);
  }
  // RTU has no transaction id: a reply that came after its timeout is still in the input
  // buffer. Discard it before asking, so it cannot be taken for the answer to this request.
  modbus_flush(ctx);
  const int rc = input ? modbus_read_input_registers(ctx, b.address, b.count, regs)
                       : modbus_read_registers(ctx, b.address, b.count, regs);
  if (rc == -1) return errno;
  return rc == b.count ? 0 : EMBBADDATA;
}

int ModbusDriver::write_registers(modbus_t* ctx, TcpTransaction& tcp,
                                  const std::uint16_t* regs) const noexcept {
  const int n = register_count(settings_.command.type);
  const int function = write_function();
  if (settings_.transport == Transport::tcp) {
    std::array<std::uint8_t, TcpTransaction::kMaxPdu> request{};
    std::array<std::uint8_t, TcpTransaction::kMaxPdu> reply{};
    int reply_len = 0;
    const int len =
        write_registers_pdu(function, settings_.command.address, n, regs, request.data());
    const int rc = tcp.transact(modbus_get_socket(ctx), settings_.unit_id, request.data(), len,
                                reply, reply_len, settings_.response_timeout_s);
    if (rc != 0) return rc;
    return check_write_reply(request.data(), len, reply.data(), reply_len);
  }
  modbus_flush(ctx);
  const int rc = function == 6 ? modbus_write_register(ctx, settings_.command.address, regs[0])
                               : modbus_write_registers(ctx, settings_.command.address, n, regs);
  return rc == -1 ? errno : 0;
}

int ModbusDriver::write_zero(modbus_t* ctx, TcpTransaction& tcp) const noexcept {
  std::array<std::uint16_t, 2> regs{};
  if (!encode_command(settings_.command, 0.0, regs.data())) return EINVAL;
  return write_registers(ctx, tcp, regs.data());
}

void ModbusDriver::open() {
  if (opened_) return;
  if (settings_.enforce_period_budget) check_timing(settings_, period_s_);
  const int n = register_count(settings_.command.type);
  if (write_function() == 6 && n != 1) {
    throw DriverError(
        "modbus: driver.modbus.command.function 6 writes one register, but command.type " +
        std::string(type_name(settings_.command.type)) + " needs two; use function 16");
  }
  plan_ = plan_reads(settings_, settings_.max_read_gap);
  buffers_.assign(plan_.blocks.size(), {});
  read_reasons_.clear();
  const int failures = settings_.max_consecutive_failures;
  for (const ReadBlock& block : plan_.blocks) {
    const bool input = block.table == Table::input;
    read_reasons_.push_back(make_reasons(
        std::string("modbus: read ") + (input ? "input" : "holding") + " registers " +
            range_text(block.address, block.count) + (input ? " (function 4)" : " (function 3)"),
        failures));
  }
  // The sample's instant is that of the block holding x (the signal the mechanical block is most
  // sensitive to in time); with one block, as usual, of every signal.
  const SignalSlot x_slot = plan_.slots[static_cast<std::size_t>(SignalId::x)];
  x_block_ = x_slot.block < 0 ? 0 : static_cast<std::size_t>(x_slot.block);
  read_event_s_ = plan_.blocks.empty()
                      ? 0.0
                      : event_after_midpoint_s(settings_, read_request_chars(),
                                               read_reply_chars(plan_.blocks[x_block_].count)) -
                            settings_.timing.input_latency_s;
  write_event_s_ = event_after_midpoint_s(settings_, write_request_chars(n), write_reply_chars()) +
                   settings_.timing.output_latency_s;
  voltage_since_ = -std::numeric_limits<double>::infinity();
  deadline_ns_ = 0;
  line_free_ns_ = 0;
  read_gate_.reset();
  write_gate_.reset();
  gap_ns_ = std::llround(kRtuFrameGapChars * char_time_s(settings_) * 1e9);
  write_reasons_ =
      make_reasons(std::string("modbus: write holding register") + (n == 1 ? " " : "s ") +
                       range_text(settings_.command.address, n) + " (function " +
                       std::to_string(write_function()) + ")",
                   failures);
  heartbeat_reasons_ =
      make_reasons("modbus: write watchdog heartbeat register " +
                       std::to_string(settings_.watchdog_register) + " (function 6)",
                   failures);
  start_reason_ = "modbus: no answer from " + endpoint() +
                  " since start; retrying with back-off (driver.modbus.reconnect), the daemon's "
                  "log names the cause";

  stats_ = {};
  stats_.output_confirmed = false;  // nothing acknowledged yet
  stats_.link_up = false;
  std::string error;
  ctx_ = make_context(error);
  const int connect_err = ctx_ == nullptr ? errno : 0;
  int err = 0;
  if (ctx_ != nullptr) {
    tcp_.reset();
    err = write_zero(ctx_, tcp_);
    if (err != 0) {
      modbus_close(ctx_);
      modbus_free(ctx_);
      ctx_ = nullptr;
    }
  }
  if (ctx_ == nullptr) {
    const bool answered = err > MODBUS_ENOBASE && err <= EMBXGTAR;
    if (err != 0) {
      error = write_reasons_.why[reason_index(err)];
      if (reason_index(err) == kOther) error += std::string(" / ") + modbus_strerror(err);
    }
    // What waiting cannot fix, or an offline run that has nobody to wait for: refuse now.
    const bool permission =
        settings_.transport == Transport::rtu && (connect_err == EACCES || connect_err == EPERM);
    if (answered || permission || !settings_.enforce_period_budget) {
      throw DriverError("modbus: cannot " + std::string(answered ? "write 0 V to " : "reach ") +
                        endpoint() + " — " + error +
                        (answered ? "; check driver.modbus.command.address and unit_id" : ""));
    }
    {
      std::lock_guard lock(sleep_mutex_);
      connect_error_ = "attempt 1: " + error;
    }
    down_reason_ = start_reason_.c_str();
    link_wanted_.store(true);
  } else {
    stats_.output_v = 0.0;
    stats_.output_confirmed = true;
    stats_.link_up = true;
    link_wanted_.store(false);
  }
  last_command_ = 0.0;
  stop_.store(false);
  // open()'s own attempt was the first when it failed.
  const std::uint64_t attempts = stats_.link_up ? 0 : 1;
  reconnector_ = std::thread([this, attempts] { reconnect_main(attempts); });
  opened_ = true;
}

std::string ModbusDriver::background_error() const {
  std::lock_guard lock(sleep_mutex_);
  return connect_error_;
}

void ModbusDriver::reconnect_main(std::uint64_t attempts_so_far) {
  double backoff = settings_.reconnect_initial_s;
  const auto nap = [this](double seconds) {
    std::unique_lock lock(sleep_mutex_);
    sleep_cv_.wait_for(lock, std::chrono::duration<double>(seconds),
                       [this] { return stop_.load(); });
  };
  std::array<std::uint16_t, kMaxRegistersPerRead> regs{};
  // Numbered so that the service logs each failed attempt once, even when the cause repeats.
  std::uint64_t attempt = attempts_so_far;
  while (!stop_.load()) {
    if (modbus_t* dead = retired_.exchange(nullptr)) {
      modbus_close(dead);
      modbus_free(dead);
    }
    if (!link_wanted_.load() || fresh_.load() != nullptr) {
      // Polled rather than signalled: the loop thread must not touch a condition variable.
      nap(0.002);
      continue;
    }
    std::string error;
    modbus_t* ctx = make_context(error);
    if (ctx != nullptr) {
      // 0 V first: the DAQ may still hold the command from before the outage. Then a read
      // proves the map answers before the loop is given the link.
      TcpTransaction tcp;
      int err = write_zero(ctx, tcp);
      const char* what = "writing 0 V";
      if (err == 0 && !plan_.blocks.empty()) {
        err = read_block(ctx, tcp, plan_.blocks.front(), regs.data());
        what = "the probe read";
      }
      if (err == 0) {
        link_wanted_.store(false);
        fresh_.store(ctx, std::memory_order_release);
        backoff = settings_.reconnect_initial_s;
        attempt = 0;
        std::lock_guard lock(sleep_mutex_);
        connect_error_.clear();
        continue;
      }
      error = std::string("connected, but ") + what +
              " failed: " + (err > MODBUS_ENOBASE ? modbus_strerror(err) : std::strerror(err));
      modbus_close(ctx);
      modbus_free(ctx);
    }
    {
      std::lock_guard lock(sleep_mutex_);
      connect_error_ = "attempt " + std::to_string(++attempt) + ": " + error;
    }
    nap(backoff);
    backoff = std::min(backoff * 2.0, settings_.reconnect_max_s);
  }
}

void ModbusDriver::adopt_fresh_link() noexcept {
  if (ctx_ != nullptr) return;
  modbus_t* ctx = fresh_.exchange(nullptr, std::memory_order_acq_rel);
  if (ctx == nullptr) return;
  ctx_ = ctx;
  tcp_.reset();
  doomed_ = false;
  if (opened_) ++stats_.reconnects;
  stats_.link_up = true;
  // The reconnect thread wrote 0 V on this link before handing it over.
  stats_.output_v = 0.0;
  stats_.output_confirmed = true;
  timeout_streak_ = 0;
  // The loop's state is stale until a fresh reading arrives, so only 0 V is sent until then.
  need_fresh_reading_ = true;
}

void ModbusDriver::doom_link(const char* reason) noexcept {
  if (ctx_ == nullptr) return;
  doomed_ = true;
  down_reason_ = reason;
  stats_.link_up = false;
}

void ModbusDriver::drop_link() noexcept {
  if (ctx_ == nullptr) return;
  // The reconnect thread frees it; a context is never used by two threads.
  modbus_t* previous = retired_.exchange(ctx_, std::memory_order_acq_rel);
  if (previous != nullptr) {
    // Cannot happen (the thread frees each retired context before publishing a new one), but
    // never leak or double-use one: keep the newer, close the older's socket only.
    modbus_close(previous);
  }
  ctx_ = nullptr;
  doomed_ = false;
  stats_.link_up = false;
  link_wanted_.store(true, std::memory_order_release);
}

const char* ModbusDriver::transaction_failed(const Reasons& reasons, int err) noexcept {
  const std::size_t index = reason_index(err);
  stats_.last_error = reasons.why[index].c_str();
  if (index >= 1 && index <= 11) {
    timeout_streak_ = 0;  // an exception is an answer: the link works
    return reasons.why[index].c_str();
  }
  if (index == kLinkLost) {
    doom_link(reasons.dropped[index].c_str());
    return reasons.dropped[index].c_str();
  }
  if (index == kBadData && settings_.transport == Transport::tcp) {
    // Bytes that are not a Modbus TCP frame: the stream is out of step, only a new connection
    // resynchronizes it. (A late reply is recognised by its transaction id and never lands
    // here.)
    doom_link(reasons.dropped[index].c_str());
    return reasons.dropped[index].c_str();
  }
  if (index == kTimeout) {
    // A streak of timeouts is a lost link (cable pulled, device rebooted): reconnect.
    if (++timeout_streak_ > settings_.max_consecutive_failures) {
      doom_link(reasons.dropped[index].c_str());
      return reasons.dropped[index].c_str();
    }
  }
  return reasons.why[index].c_str();
}

IoResult ModbusDriver::tolerate(int& streak, const char* reason) noexcept {
  ++streak;
  if (streak > settings_.max_consecutive_failures) return IoResult::fail(reason);
  return IoResult{IoStatus::no_data, reason};
}

IoResult ModbusDriver::read(const CycleTime& now, Sample& out) noexcept {
  adopt_fresh_link();
  if (ctx_ == nullptr || doomed_) {
    ++stats_.read_errors;
    return tolerate(read_streak_, down_reason_[0] ? down_reason_ : kLinkDown);
  }
  deadline_ns_ = now.deadline_ns;
  deadline_t_ = now.t;
  std::int64_t sampled_ns = 0;  // midpoint of the transaction that read x
  for (std::size_t i = 0; i < plan_.blocks.size(); ++i) {
    const std::int64_t begin_ns = stamping() ? monotonic_ns() : 0;
    const int err = read_block(ctx_, tcp_, plan_.blocks[i], buffers_[i].data());
    if (stamping()) {
      // Only the x block's successful reads teach the gate the usual read; the others only
      // occupy the line.
      if (i == x_block_ && err == 0) {
        sampled_ns = transaction_stamp(begin_ns, read_gate_);
      } else {
        mark_line_busy(monotonic_ns());
      }
    }
    stats_.late_replies = tcp_.late_replies();
    if (err != 0) {
      ++stats_.read_errors;
      return tolerate(read_streak_, transaction_failed(read_reasons_[i], err));
    }
  }
  const auto sigs = signals_of(settings_);
  std::array<double, kSignalCount> values{};
  for (std::size_t s = 0; s < kSignalCount; ++s) {
    const SignalSlot slot = plan_.slots[s];
    values[s] =
        slot.block < 0
            ? kNotMeasured
            : decode_register_signal(
                  *sigs[s], buffers_[static_cast<std::size_t>(slot.block)].data() + slot.offset);
  }
  out.t = stamping() ? loop_time(sampled_ns) + read_event_s_ : now.t;
  out.voltage_since = voltage_since_;
  out.x = values[static_cast<std::size_t>(SignalId::x)];
  out.xdot = values[static_cast<std::size_t>(SignalId::xdot)];
  out.temperature = values[static_cast<std::size_t>(SignalId::temperature)];
  // Without a read-back the DAC holds what was last accepted over the interval now ending.
  out.voltage = settings_.voltage.present ? values[static_cast<std::size_t>(SignalId::voltage)]
                                          : last_command_;
  read_streak_ = 0;
  timeout_streak_ = 0;
  need_fresh_reading_ = false;
  ++stats_.reads;
  return IoResult::ok();
}

void ModbusDriver::feed_watchdog() noexcept {
  if (settings_.watchdog_register < 0 || ctx_ == nullptr || doomed_) return;
  if (++heartbeat_cycle_ < settings_.watchdog_every) return;
  heartbeat_cycle_ = 0;
  heartbeat_value_ ^= 1u;
  int err = 0;
  if (settings_.transport == Transport::tcp) {
    std::array<std::uint8_t, TcpTransaction::kMaxPdu> request{};
    std::array<std::uint8_t, TcpTransaction::kMaxPdu> reply{};
    int reply_len = 0;
    const int len =
        write_registers_pdu(6, settings_.watchdog_register, 1, &heartbeat_value_, request.data());
    err = tcp_.transact(modbus_get_socket(ctx_), settings_.unit_id, request.data(), len, reply,
                        reply_len, settings_.response_timeout_s);
    if (err == 0) err = check_write_reply(request.data(), len, reply.data(), reply_len);
  } else {
    modbus_flush(ctx_);
    if (modbus_write_register(ctx_, settings_.watchdog_register, heartbeat_value_) == -1) {
      err = errno;
    }
  }
  if (err != 0) {
    ++stats_.write_errors;
    transaction_failed(heartbeat_reasons_, err);
  }
}

bool ModbusDriver::write_command(double volts, int& err) noexcept {
  std::array<std::uint16_t, 2> regs{};
  if (!encode_command(settings_.command, volts, regs.data())) {
    err = EINVAL;
    return false;
  }
  const std::int64_t begin_ns = stamping() ? monotonic_ns() : 0;
  err = write_registers(ctx_, tcp_, regs.data());
  stats_.late_replies = tcp_.late_replies();
  if (err != 0) {
    if (stamping()) {
      const std::int64_t end_ns = monotonic_ns();
      if (err == ETIMEDOUT) {
        // The device may have applied it all the same (its reply was late, or lost), and the
        // read-back voltage of the next sample will then be the new one: take it to have landed
        // where a write usually lands. Had it not, the next sample's voltage is the previous
        // one and the instant is moot (V² the same on both sides). Keeping the last write's
        // instant instead would have the new voltage act over the whole interval.
        voltage_since_ =
            loop_time(write_gate_.guess(line_begin_ns(begin_ns, end_ns), end_ns, deadline_ns_)) +
            write_event_s_;
      }
      mark_line_busy(end_ns);
    }
    // Timed out or refused: the device may hold the new value or the old one.
    stats_.output_confirmed = false;
    return false;
  }
  if (stamping()) {
    voltage_since_ = loop_time(transaction_stamp(begin_ns, write_gate_)) + write_event_s_;
  }
  stats_.output_v = volts;
  stats_.output_confirmed = true;
  return true;
}

void ModbusDriver::mark_line_busy(std::int64_t end_ns) noexcept {
  line_free_ns_ = end_ns + gap_ns_;
}

std::int64_t ModbusDriver::transaction_end_ns(std::int64_t begin_ns) const noexcept {
  const std::int64_t now = monotonic_ns();
  if (settings_.transport != Transport::tcp) return now;
  // When the kernel received the reply, if it says so and the stamp is plausible (not before
  // the request was sent: bytes buffered earlier; not after now: a clock step).
  const std::int64_t received = tcp_.reply_received_ns();
  return received > begin_ns && received <= now ? received : now;
}

std::int64_t ModbusDriver::line_begin_ns(std::int64_t begin_ns,
                                         std::int64_t end_ns) const noexcept {
  return std::max(begin_ns, std::min(line_free_ns_, end_ns));
}

std::int64_t ModbusDriver::transaction_stamp(std::int64_t begin_ns, StampGate& gate) noexcept {
  const std::int64_t end_ns = transaction_end_ns(begin_ns);
  begin_ns = line_begin_ns(begin_ns, end_ns);
  mark_line_busy(end_ns);
  const StampGate::Stamp stamp = gate.judge(begin_ns, end_ns, deadline_ns_);
  if (stamp.stretched) ++stats_.stretched_stamps;
  return stamp.midpoint_ns;
}

double ModbusDriver::loop_time(std::int64_t monotonic_ns) const noexcept {
  return deadline_t_ + static_cast<double>(monotonic_ns - deadline_ns_) * 1e-9;
}

IoResult ModbusDriver::write_voltage(double volts) noexcept {
  adopt_fresh_link();
  if (!std::isfinite(volts) || volts < settings_.command.min_volts ||
      volts > settings_.command.max_volts) {
    safe_state();
    ++stats_.write_errors;
    return IoResult::fail(std::isfinite(volts) ? kOutOfRange : kNotFinite);
  }
  if (need_fresh_reading_ || doomed_) volts = 0.0;
  if (ctx_ == nullptr) {
    if (stats_.output_v != 0.0) stats_.output_confirmed = false;
    ++stats_.write_errors;
    return tolerate(write_streak_, down_reason_[0] ? down_reason_ : kLinkDown);
  }
  if (doomed_) {
    // The link is about to be dropped: its last use is an attempt at 0 V.
    safe_state();
    ++stats_.write_errors;
    return tolerate(write_streak_, down_reason_);
  }
  int err = 0;
  if (!write_command(volts, err)) {
    ++stats_.write_errors;
    if (err == EINVAL) return IoResult::fail(kNotEncodable);
    return tolerate(write_streak_, transaction_failed(write_reasons_, err));
  }
  last_command_ = volts;
  write_streak_ = 0;
  ++stats_.writes;
  feed_watchdog();
  return IoResult::ok();
}

void ModbusDriver::safe_state() noexcept {
  adopt_fresh_link();
  if (ctx_ == nullptr) {
    // Nothing reachable: the DAQ holds what it last acknowledged; its own watchdog is the last
    // line (docs/driver-modbus.md).
    if (stats_.output_v != 0.0) stats_.output_confirmed = false;
    return;
  }
  int err = 0;
  if (write_command(0.0, err)) {
    last_command_ = 0.0;
    ++stats_.writes;
    feed_watchdog();  // the daemon is alive and in control, holding 0 V
  } else {
    ++stats_.write_errors;
    if (!doomed_) transaction_failed(write_reasons_, err);
  }
  if (doomed_) drop_link();
}

DriverStats ModbusDriver::stats() const noexcept {
  return stats_;
}

void ModbusDriver::close() noexcept {
  if (reconnector_.joinable()) {
    {
      std::lock_guard lock(sleep_mutex_);
      stop_.store(true);
    }
    sleep_cv_.notify_all();
    reconnector_.join();
  }
  if (opened_) safe_state();
  for (modbus_t* ctx : {ctx_, fresh_.exchange(nullptr), retired_.exchange(nullptr)}) {
    if (ctx != nullptr) {
      modbus_close(ctx);
      modbus_free(ctx);
    }
  }
  ctx_ = nullptr;
  doomed_ = false;
  stats_.link_up = false;
  opened_ = false;
}

}  // namespace scp::drivers::modbus

#include "drivers/modbus/modbus_driver.hpp"

#include <modbus/modbus.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <utility>

#include "common/clock.hpp"
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
  r.why[kLineBusy] = what +
                     ": the line never fell silent before the request (a late reply still "
                     "arriving, another master on the bus, or noise)";
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
  if (err == EBUSY) return kLineBusy;
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

int ModbusDriver::write_command_registers(ModbusLink& link,
                                          const std::uint16_t* registers) const noexcept {
  return link.write_registers(write_function(), settings_.command.address,
                              register_count(settings_.command.type), registers);
}

int ModbusDriver::write_zero(ModbusLink& link) const noexcept {
  std::array<std::uint16_t, 2> regs{};
  if (!encode_command(settings_.command, 0.0, regs.data())) return EINVAL;
  return write_command_registers(link, regs.data());
}

void ModbusDriver::open() {
  if (opened_) return;
  if (settings_.enforce_period_budget) check_timing(settings_, period_s_);
  prepare();
  connect_first();
  last_command_ = 0.0;
  stop_.store(false);
  // open()'s own attempt was the first when it failed.
  const std::uint64_t attempts = stats_.link_up ? 0 : 1;
  reconnector_ = std::thread([this, attempts] { reconnect_main(attempts); });
  opened_ = true;
}

void ModbusDriver::prepare() {
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
  // A cycle's I/O fits its period (check_timing() approved n x response_timeout within it); an
  // offline run has no wall-clock period to fit.
  cycle_budget_ns_ = settings_.enforce_period_budget ? std::llround(period_s_ * 1e9)
                                                     : std::numeric_limits<std::int64_t>::max() / 2;
  // One write of 0 V outside a cycle: the silence before its request, then its reply's wait.
  safe_budget_ns_ =
      std::llround(settings_.response_timeout_s * 1e9) +
      (settings_.transport == Transport::rtu
           ? rtu_silence_ns(std::llround(char_time_s(settings_) * 1e9), settings_.baud)
           : 0);
}

void ModbusDriver::connect_first() {
  stats_ = {};
  stats_.output_confirmed = false;  // nothing acknowledged yet
  stats_.link_up = false;
  late_before_link_ = 0;
  std::string error;
  link_ = ModbusLink::connect(settings_, error);
  const int connect_err = link_ == nullptr ? errno : 0;
  const int err = link_ == nullptr ? 0 : write_zero(*link_);
  if (err == 0 && link_ != nullptr) {
    stats_.output_v = 0.0;
    stats_.output_confirmed = true;
    stats_.link_up = true;
    link_wanted_.store(false);
    return;
  }
  link_.reset();
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
}

std::string ModbusDriver::background_error() const {
  std::lock_guard lock(sleep_mutex_);
  return connect_error_;
}

std::unique_ptr<ModbusLink> ModbusDriver::try_link(std::string& error) const {
  std::unique_ptr<ModbusLink> link = ModbusLink::connect(settings_, error);
  if (link == nullptr) return nullptr;
  // 0 V first: the DAQ may still hold the command from before the outage. Then a read proves the
  // map answers before the loop is given the link.
  std::array<std::uint16_t, kMaxRegistersPerRead> regs{};
  int err = write_zero(*link);
  const char* what = "writing 0 V";
  if (err == 0 && !plan_.blocks.empty()) {
    err = link->read_registers(plan_.blocks.front(), regs.data());
    what = "the probe read";
  }
  if (err == 0) return link;
  error = std::string("connected, but ") + what +
          " failed: " + (err > MODBUS_ENOBASE ? modbus_strerror(err) : std::strerror(err));
  return nullptr;
}

void ModbusDriver::reconnect_main(std::uint64_t attempts_so_far) {
  double backoff = settings_.reconnect_initial_s;
  const auto nap = [this](double seconds) {
    std::unique_lock lock(sleep_mutex_);
    sleep_cv_.wait_for(lock, std::chrono::duration<double>(seconds),
                       [this] { return stop_.load(); });
  };
  // Numbered so that the service logs each failed attempt once, even when the cause repeats.
  std::uint64_t attempt = attempts_so_far;
  while (!stop_.load()) {
    delete retired_.exchange(nullptr);  // a link the loop dropped
    if (!link_wanted_.load() || fresh_.load() != nullptr) {
      // Polled rather than signalled: the loop thread must not touch a condition variable.
      nap(0.002);
      continue;
    }
    std::string error;
    if (std::unique_ptr<ModbusLink> link = try_link(error)) {
      link_wanted_.store(false);
      fresh_.store(link.release(), std::memory_order_release);
      backoff = settings_.reconnect_initial_s;
      attempt = 0;
      std::lock_guard lock(sleep_mutex_);
      connect_error_.clear();
      continue;
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
  if (link_ != nullptr) return;
  ModbusLink* link = fresh_.exchange(nullptr, std::memory_order_acq_rel);
  if (link == nullptr) return;
  link_.reset(link);  // link_ was empty: nothing is freed here
  late_before_link_ = stats_.late_replies;
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
  if (link_ == nullptr) return;
  doomed_ = true;
  down_reason_ = reason;
  stats_.link_up = false;
}

void ModbusDriver::drop_link() noexcept {
  if (link_ == nullptr) return;
  // The reconnect thread destroys it; a link is never used by two threads.
  ModbusLink* previous = retired_.exchange(link_.release(), std::memory_order_acq_rel);
  // Cannot happen (the thread destroys each retired link before publishing a new one); were it
  // to, destroying it here beats leaking its descriptor.
  delete previous;
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
  if (index == kTimeout && settings_.transport == Transport::tcp) {
    // A streak of timeouts over TCP is a lost connection (cable pulled, device rebooted, a
    // half-open socket): reconnect. A serial port does not get better for being reopened: the
    // next cycles keep asking (the loop faults and commands 0 V meanwhile), and a port that is
    // gone fails with its own errors (EIO, ENODEV), which drop the link.
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
  if (link_ == nullptr || doomed_) {
    ++stats_.read_errors;
    return tolerate(read_streak_, down_reason_[0] ? down_reason_ : kLinkDown);
  }
  deadline_ns_ = now.deadline_ns;
  deadline_t_ = now.t;
  // The cycle's transactions share one period: each waits for its reply at most the response
  // timeout, a slow one leaves the others less, and together they never take longer than a
  // period. Counted from now, not from the deadline, so that a cycle that woke late still gets
  // its whole share.
  link_->limit_until(clock::monotonic_ns() + cycle_budget_ns_);
  std::int64_t sampled_ns = 0;  // midpoint of the transaction that read x
  for (std::size_t i = 0; i < plan_.blocks.size(); ++i) {
    const std::int64_t called_ns = stamping() ? clock::monotonic_ns() : 0;
    const int err = link_->read_registers(plan_.blocks[i], buffers_[i].data());
    if (stamping()) {
      // Only the x block's successful reads teach the gate the usual read; the others only
      // occupy the line.
      if (i == x_block_ && err == 0) {
        sampled_ns = transaction_stamp(called_ns, read_gate_);
      } else {
        mark_line_busy(clock::monotonic_ns());
      }
    }
    stats_.late_replies = late_before_link_ + link_->late_replies();
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
  // The command landed before this read was even sent (one transaction at a time on the link),
  // so before the sample; a load spike's stamps, each placed where its transaction usually lies
  // (StampGate), may say otherwise by tens of µs. A replay refuses such a row.
  out.voltage_since = std::min(voltage_since_, out.t);
  out.x = values[static_cast<std::size_t>(SignalId::x)];
  out.xdot = values[static_cast<std::size_t>(SignalId::xdot)];
  out.temperature = values[static_cast<std::size_t>(SignalId::temperature)];
  out.current = values[static_cast<std::size_t>(SignalId::current)];  // NaN when not in the map
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
  if (settings_.watchdog_register < 0 || link_ == nullptr || doomed_) return;
  if (++heartbeat_cycle_ < settings_.watchdog_every) return;
  heartbeat_cycle_ = 0;
  heartbeat_value_ ^= 1u;
  const int err = link_->write_registers(6, settings_.watchdog_register, 1, &heartbeat_value_);
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
  const std::int64_t called_ns = stamping() ? clock::monotonic_ns() : 0;
  err = write_command_registers(*link_, regs.data());
  stats_.late_replies = late_before_link_ + link_->late_replies();
  if (err != 0) {
    if (stamping()) {
      const Span span = last_span(called_ns);
      if (err == ETIMEDOUT) {
        // The device may have applied it all the same (its reply was late, or lost), and the
        // read-back voltage of the next sample will then be the new one: take it to have landed
        // where a write usually lands. Had it not, the next sample's voltage is the previous
        // one and the instant is moot (V² the same on both sides). Keeping the last write's
        // instant instead would have the new voltage act over the whole interval.
        voltage_since_ =
            loop_time(write_gate_.guess(span.begin_ns, span.end_ns, deadline_ns_)) + write_event_s_;
      }
      mark_line_busy(span.end_ns);
    }
    // Timed out or refused: the device may hold the new value or the old one.
    stats_.output_confirmed = false;
    return false;
  }
  if (stamping()) {
    voltage_since_ = loop_time(transaction_stamp(called_ns, write_gate_)) + write_event_s_;
  }
  stats_.output_v = volts;
  stats_.output_confirmed = true;
  return true;
}

void ModbusDriver::mark_line_busy(std::int64_t end_ns) noexcept {
  line_free_ns_ = end_ns + gap_ns_;
}

ModbusDriver::Span ModbusDriver::last_span(std::int64_t called_ns) const noexcept {
  const std::int64_t sent = link_->request_sent_ns();
  const std::int64_t received = link_->reply_received_ns();
  const std::int64_t begin_ns = sent > 0 ? sent : called_ns;
  const std::int64_t end_ns = received >= begin_ns ? received : clock::monotonic_ns();
  return {line_begin_ns(begin_ns, end_ns), end_ns};
}

std::int64_t ModbusDriver::line_begin_ns(std::int64_t begin_ns,
                                         std::int64_t end_ns) const noexcept {
  return std::max(begin_ns, std::min(line_free_ns_, end_ns));
}

std::int64_t ModbusDriver::transaction_stamp(std::int64_t called_ns, StampGate& gate) noexcept {
  const Span span = last_span(called_ns);
  mark_line_busy(span.end_ns);
  const StampGate::Stamp stamp = gate.judge(span.begin_ns, span.end_ns, deadline_ns_);
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
  if (link_ == nullptr) {
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
  if (link_ == nullptr) {
    // Nothing reachable: the DAQ holds what it last acknowledged; its own watchdog is the last
    // line (docs/driver-modbus.md).
    if (stats_.output_v != 0.0) stats_.output_confirmed = false;
    return;
  }
  // Called outside a cycle too (the loop's shutdown, a fault raised late in a cycle), when the
  // cycle's budget may have run out: an RTU request would then never be sent and a TCP reply
  // never awaited. 0 V is worth an overrun: a whole transaction's time, from now.
  link_->limit_until(clock::monotonic_ns() + safe_budget_ns_);
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
  link_.reset();
  delete fresh_.exchange(nullptr);
  delete retired_.exchange(nullptr);
  doomed_ = false;
  stats_.link_up = false;
  opened_ = false;
}

}  // namespace scp::drivers::modbus

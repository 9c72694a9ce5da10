#include "drivers/modbus/modbus_driver.hpp"

#include <modbus/modbus.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <utility>

#include "drivers/modbus/register_codec.hpp"
#include "drivers/modbus/timing.hpp"

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

std::array<std::string, 14> make_reasons(const std::string& what) {
  std::array<std::string, 14> r;
  r[0] = what + ": invalid reply (CRC, framing or unit id mismatch)";
  for (int code = 1; code <= 11; ++code) {
    r[static_cast<std::size_t>(code)] =
        what + ": exception " + std::to_string(code) + " (" + exception_name(code) + ")";
  }
  r[12] = what + ": no reply within driver.modbus.response_timeout";
  r[13] = what + ": connection lost, reconnecting";
  return r;
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
    : settings_(std::move(settings)), period_s_(period_s) {}

ModbusDriver::~ModbusDriver() {
  close();
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
    modbus_free(ctx);
    return nullptr;
  }
  return ctx;
}

void ModbusDriver::open() {
  if (opened_) return;
  if (settings_.enforce_period_budget) check_timing(settings_, period_s_);
  plan_ = plan_reads(settings_, settings_.max_read_gap);
  buffers_.assign(plan_.blocks.size(), {});
  read_reasons_.clear();
  for (const ReadBlock& block : plan_.blocks) {
    const bool input = block.table == Table::input;
    read_reasons_.push_back(make_reasons(
        std::string("modbus: read ") + (input ? "input" : "holding") + " registers " +
        range_text(block.address, block.count) + (input ? " (function 4)" : " (function 3)")));
  }
  const int n = register_count(settings_.command.type);
  write_reasons_ = make_reasons(std::string("modbus: write holding register") +
                                (n == 1 ? " " : "s ") + range_text(settings_.command.address, n) +
                                (n == 1 ? " (function 6)" : " (function 16)"));

  std::string error;
  ctx_ = make_context(error);
  if (ctx_ == nullptr) throw DriverError("modbus: cannot connect to " + endpoint() + ": " + error);
  int err = 0;
  if (!write_command(0.0, err)) {
    const std::string what = (err > MODBUS_ENOBASE && err <= EMBXGTAR)
                                 ? write_reasons_[static_cast<std::size_t>(err - MODBUS_ENOBASE)]
                                 : write_reasons_[kOther] + " / " + modbus_strerror(err);
    modbus_close(ctx_);
    modbus_free(ctx_);
    ctx_ = nullptr;
    throw DriverError("modbus: cannot write 0 V to " + endpoint() + " — " + what +
                      "; check driver.modbus.command.address and unit_id");
  }
  last_command_ = 0.0;
  stats_ = {};
  stats_.link_up = true;
  stop_.store(false);
  link_wanted_.store(false);
  reconnector_ = std::thread([this] { reconnect_main(); });
  opened_ = true;
}

bool ModbusDriver::probe(modbus_t* ctx) {
  if (plan_.blocks.empty()) return true;
  std::array<std::uint16_t, kMaxRegistersPerRead> regs{};
  const ReadBlock& b = plan_.blocks.front();
  const int rc = b.table == Table::input
                     ? modbus_read_input_registers(ctx, b.address, b.count, regs.data())
                     : modbus_read_registers(ctx, b.address, b.count, regs.data());
  return rc == b.count;
}

void ModbusDriver::reconnect_main() {
  double backoff = settings_.reconnect_initial_s;
  const auto nap = [this](double seconds) {
    std::unique_lock lock(sleep_mutex_);
    sleep_cv_.wait_for(lock, std::chrono::duration<double>(seconds),
                       [this] { return stop_.load(); });
  };
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
    if (ctx != nullptr && probe(ctx)) {
      link_wanted_.store(false);
      fresh_.store(ctx, std::memory_order_release);
      backoff = settings_.reconnect_initial_s;
      continue;
    }
    if (ctx != nullptr) {
      modbus_close(ctx);
      modbus_free(ctx);
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
  ++stats_.reconnects;
  stats_.link_up = true;
  timeout_streak_ = 0;
  // The DAQ may still hold the last command from before the outage; the loop's state is stale
  // until a fresh reading arrives, so only 0 V is sent until then.
  need_fresh_reading_ = true;
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
  stats_.link_up = false;
  link_wanted_.store(true, std::memory_order_release);
}

const char* ModbusDriver::transaction_failed(const Reasons& reasons, int err) noexcept {
  if (err > MODBUS_ENOBASE && err <= EMBXGTAR) {
    timeout_streak_ = 0;
    return reasons[static_cast<std::size_t>(err - MODBUS_ENOBASE)].c_str();
  }
  if (is_link_error(err)) {
    drop_link();
    return reasons[kLinkLost].c_str();
  }
  // A late reply would be taken as the answer to the next request: discard what is buffered
  // (non-blocking for TCP and RTU).
  modbus_flush(ctx_);
  if (err == EMBBADDATA && settings_.transport == Transport::tcp) {
    // A reply to an earlier request (it came after its timeout and after the flush): every
    // later transaction would read its predecessor's reply. A new connection resynchronizes.
    drop_link();
    return reasons[kOther].c_str();
  }
  if (err == ETIMEDOUT) {
    // A streak of timeouts is a lost link (cable pulled, device rebooted): reconnect.
    if (++timeout_streak_ > settings_.max_consecutive_failures) drop_link();
    return reasons[kTimeout].c_str();
  }
  return reasons[kOther].c_str();
}

IoResult ModbusDriver::tolerate(int& streak, const char* reason) noexcept {
  ++streak;
  if (streak > settings_.max_consecutive_failures) return IoResult::fail(reason);
  return IoResult{IoStatus::no_data, reason};
}

IoResult ModbusDriver::read(const CycleTime& now, Sample& out) noexcept {
  adopt_fresh_link();
  if (ctx_ == nullptr) {
    ++stats_.read_errors;
    return tolerate(read_streak_, kLinkDown);
  }
  for (std::size_t i = 0; i < plan_.blocks.size(); ++i) {
    const ReadBlock& b = plan_.blocks[i];
    const int rc = b.table == Table::input
                       ? modbus_read_input_registers(ctx_, b.address, b.count, buffers_[i].data())
                       : modbus_read_registers(ctx_, b.address, b.count, buffers_[i].data());
    if (rc != b.count) {
      const int err = rc == -1 ? errno : EMBBADDATA;
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
  out.t = now.t;
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

bool ModbusDriver::write_command(double volts, int& err) noexcept {
  std::array<std::uint16_t, 2> regs{};
  if (!encode_command(settings_.command, volts, regs.data())) {
    err = EINVAL;
    return false;
  }
  const int n = register_count(settings_.command.type);
  const int rc = n == 1 ? modbus_write_register(ctx_, settings_.command.address, regs[0])
                        : modbus_write_registers(ctx_, settings_.command.address, n, regs.data());
  if (rc == -1) {
    err = errno;
    return false;
  }
  return true;
}

IoResult ModbusDriver::write_voltage(double volts) noexcept {
  adopt_fresh_link();
  if (!std::isfinite(volts) || volts < settings_.command.min_volts ||
      volts > settings_.command.max_volts) {
    safe_state();
    ++stats_.write_errors;
    return IoResult::fail(std::isfinite(volts) ? kOutOfRange : kNotFinite);
  }
  if (need_fresh_reading_) volts = 0.0;
  if (ctx_ == nullptr) {
    ++stats_.write_errors;
    return tolerate(write_streak_, kLinkDown);
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
  return IoResult::ok();
}

void ModbusDriver::safe_state() noexcept {
  adopt_fresh_link();
  if (ctx_ == nullptr) return;  // nothing reachable; the DAQ's own watchdog is the last line
  int err = 0;
  if (write_command(0.0, err)) {
    last_command_ = 0.0;
    ++stats_.writes;
  } else {
    ++stats_.write_errors;
    transaction_failed(write_reasons_, err);
  }
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
  stats_.link_up = false;
  opened_ = false;
}

}  // namespace scp::drivers::modbus

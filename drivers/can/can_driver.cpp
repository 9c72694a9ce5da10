#include "drivers/can/can_driver.hpp"

#include <linux/can/error.h>
#include <poll.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <utility>

#include "drivers/can/signal_codec.hpp"

namespace scp::drivers::can {
namespace {

canid_t wire_id(const CanSignal& sig) noexcept {
  return sig.extended ? (sig.frame_id | CAN_EFF_FLAG) : sig.frame_id;
}

const CanSettings& validated(const CanSettings& s) {
  if (auto problem = validate_can_settings(s)) {
    throw DriverError("can." + problem->key + ": " + problem->message);
  }
  return s;
}

}  // namespace

CanDriver::CanDriver(const CanSettings& settings) : settings_(validated(settings)) {
  for (int i = 0; i < kSignalCount; ++i) {
    const CanSignal& sig = *signal_at(settings_, i);
    if (!sig.present) continue;
    const canid_t id = wire_id(sig);
    bool known = false;
    for (std::size_t k = 0; k < n_ids_; ++k) known = known || ids_[k] == id;
    if (!known) ids_[n_ids_++] = id;
    // Messages are formatted now, because read() may not allocate.
    std::snprintf(stale_reason_[i].data(), stale_reason_[i].size(),
                  "CAN signal %s stale for %g s (frame 0x%X on %s): is the DAQ node sending?",
                  kSignalNames[i], sig.stale_timeout_s, sig.frame_id, settings_.interface.c_str());
    std::snprintf(never_reason_[i].data(), never_reason_[i].size(),
                  "CAN signal %s never received (frame 0x%X on %s): check `candump %s`",
                  kSignalNames[i], sig.frame_id, settings_.interface.c_str(),
                  settings_.interface.c_str());
  }
  std::snprintf(bus_off_reason_, sizeof bus_off_reason_,
                "CAN bus-off on %s: waiting for the controller to restart (`ip link set %s type "
                "can restart-ms 100`)",
                settings_.interface.c_str(), settings_.interface.c_str());
  std::snprintf(down_reason_, sizeof down_reason_,
                "CAN interface %s down (ENETDOWN): `ip link set %s up type can bitrate 500000`",
                settings_.interface.c_str(), settings_.interface.c_str());
  std::snprintf(tx_full_reason_, sizeof tx_full_reason_,
                "CAN transmit queue full %d times in a row on %s: no node acknowledges, or the "
                "bus is saturated",
                settings_.tx_full_fault_after, settings_.interface.c_str());
}

CanDriver::CanDriver(const CanSettings& settings, CanChannel channel) : CanDriver(settings) {
  channel_ = std::move(channel);
  have_channel_ = channel_.valid();
}

void CanDriver::open() {
  if (!have_channel_) {
    const int inherited = inherited_fd(settings_.interface);
    // interface "fd:N": the socket was opened by whoever started us (a test's socketpair, a
    // supervisor holding the bus); it carries can_frame records like a CAN_RAW socket.
    channel_ = inherited >= 0 ? CanChannel(inherited)
                              : open_socketcan(settings_.interface, receive_ids(), settings_.fd);
    have_channel_ = true;
  }
  started_ = false;
  bus_off_ = false;
  link_down_ = false;
  received_ = {};
  fresh_ = {};
  tx_full_in_a_row_ = 0;
  have_last_sent_ = false;
  last_command_ = 0.0;
  // No heartbeat yet: it means "the loop is cycling", and start-up may take longer than the
  // DAQ's timeout between open() and the first cycle (the DAQ arms at the first heartbeat).
  heartbeat_due_ = false;
  next_heartbeat_t_ = 0.0;
  // An interface that is down (ENETDOWN) is not refused: like a Modbus DAQ absent at start it is
  // awaited, as it would be if it went down later. read() reports it until frames flow, the loop
  // holds STARTING at 0 V, and driver.start_timeout_s bounds the wait.
  (void)send_command(0.0, true);
}

void CanDriver::handle_error_frame(const canfd_frame& f) noexcept {
  ++counters_.error_frames;
  const canid_t cls = f.can_id & CAN_ERR_MASK;
  if (cls & CAN_ERR_BUSOFF) {
    if (!bus_off_) ++counters_.bus_off;
    bus_off_ = true;
  }
  if (cls & CAN_ERR_CRTL) ++counters_.controller_problems;
  if (cls & CAN_ERR_RESTARTED) {
    if (bus_off_) {
      ++counters_.restarts;
      ++stats_.reconnects;
    }
    bus_off_ = false;
  }
  if (cls & ~(CAN_ERR_BUSOFF | CAN_ERR_CRTL | CAN_ERR_RESTARTED)) ++counters_.other_errors;
}

void CanDriver::handle_data_frame(const canfd_frame& f, double t) noexcept {
  if (f.can_id & CAN_RTR_FLAG) {
    ++counters_.unexpected_frames;
    return;
  }
  const bool ext = (f.can_id & CAN_EFF_FLAG) != 0;
  const std::uint32_t id = f.can_id & (ext ? CAN_EFF_MASK : CAN_SFF_MASK);
  bool used = false;
  for (int i = 0; i < kSignalCount; ++i) {
    const CanSignal& sig = *signal_at(settings_, i);
    if (!sig.present || sig.frame_id != id || sig.extended != ext) continue;
    if (!signal_fits(sig, f.len)) continue;  // a short frame: counted below if nothing fit
    value_[i] = decode_signal(sig, f.data, f.len);
    rx_t_[i] = t;
    received_[i] = true;
    fresh_[i] = true;
    used = true;
  }
  if (!used) {
    ++counters_.unexpected_frames;
    return;
  }
  ++counters_.frames;
  link_down_ = false;
  // Frames flowing again mean the controller left bus-off even if we missed CAN_ERR_RESTARTED.
  if (bus_off_) {
    bus_off_ = false;
    ++counters_.restarts;
    ++stats_.reconnects;
  }
}

bool CanDriver::all_present_fresh() const noexcept {
  for (int i = 0; i < kSignalCount; ++i) {
    if (signal_at(settings_, i)->present && !fresh_[i]) return false;
  }
  return true;
}

IoResult CanDriver::read(const CycleTime& now, Sample& out) noexcept {
  if (!channel_.valid()) {
    ++stats_.read_errors;
    return IoResult::fail("CAN driver not open");
  }
  if (!std::isfinite(now.t)) {
    ++stats_.read_errors;
    return IoResult::fail("CAN read: non-finite loop time");
  }
  if (!started_) {
    started_ = true;
    start_t_ = now.t;
    next_heartbeat_t_ = now.t;
  }
  // 1 ns of slack: loop times k·period and the sum of heartbeat periods round differently.
  if (settings_.heartbeat.enabled && now.t >= next_heartbeat_t_ - 1e-9) {
    heartbeat_due_ = true;
    const double period = settings_.heartbeat.period_ms * 1e-3;
    next_heartbeat_t_ += period;
    // After a stall the schedule restarts from now instead of sending a burst to catch up.
    if (next_heartbeat_t_ <= now.t - 1e-9) next_heartbeat_t_ = now.t + period;
  }
  fresh_ = {};
  // Lock-step (read_wait_s > 0): wait, bounded, until every present signal is new this cycle.
  double wait_left_ms = settings_.read_wait_s * 1e3;
  for (int n = 0; n < settings_.max_frames_per_cycle; ++n) {
    canfd_frame f{};
    bool is_fd = false;
    const RxStatus rx = channel_.receive(f, is_fd);
    if (rx == RxStatus::empty) {
      if (wait_left_ms <= 0.0 || all_present_fresh()) break;
      pollfd p{channel_.fd(), POLLIN, 0};
      const int ms = static_cast<int>(std::ceil(std::min(wait_left_ms, 100.0)));
      if (::poll(&p, 1, ms) <= 0) wait_left_ms -= ms;  // timeout (or EINTR): less time left
      continue;
    }
    if (rx == RxStatus::frame) {
      if (f.can_id & CAN_ERR_FLAG) {
        handle_error_frame(f);
      } else {
        handle_data_frame(f, now.t);
      }
    } else if (rx == RxStatus::malformed) {
      ++counters_.unexpected_frames;
    } else if (rx == RxStatus::down) {
      link_down_ = true;
      break;
    } else {
      ++stats_.read_errors;
      return IoResult::fail(io_failure("receive"));
    }
  }
  counters_.kernel_drops = channel_.kernel_drops();
  if (link_down_) {
    ++stats_.read_errors;
    return IoResult::fail(down_reason_);
  }
  if (bus_off_) {
    ++stats_.read_errors;
    return IoResult::fail(bus_off_reason_);
  }

  bool waiting = false;
  bool any_fresh = false;
  for (int i = 0; i < kSignalCount; ++i) {
    const CanSignal& sig = *signal_at(settings_, i);
    if (!sig.present) continue;
    if (!received_[i]) {
      if (now.t - start_t_ > sig.stale_timeout_s) {
        ++stats_.read_errors;
        return IoResult::fail(never_reason_[i].data());
      }
      waiting = true;
      continue;
    }
    if (now.t - rx_t_[i] > sig.stale_timeout_s) {
      ++stats_.read_errors;
      return IoResult::fail(stale_reason_[i].data());
    }
    any_fresh = any_fresh || fresh_[i];
  }
  if (waiting || !any_fresh) return {IoStatus::no_data, "no new CAN frame this cycle"};

  out.t = now.t;
  out.x = value_[0];
  out.xdot = settings_.xdot.present ? value_[1] : kNotMeasured;
  out.temperature = value_[2];
  // Without a read-back, the command sent last cycle is what the DAC held over this interval.
  out.voltage = settings_.voltage.present ? value_[3] : last_command_;
  out.current = settings_.current.present ? value_[4] : kNotMeasured;
  ++stats_.reads;
  return IoResult::ok();
}

IoResult CanDriver::send_command(double volts, bool force) noexcept {
  const CanSignal& sig = settings_.command.signal;
  canfd_frame f{};
  f.can_id = wire_id(sig);
  f.len = static_cast<std::uint8_t>(sig.dlc);
  if (!encode_signal(sig, volts, f.data, f.len)) {
    ++stats_.write_errors;
    return IoResult::fail("CAN command: voltage not encodable");
  }
  if (!force && !settings_.command.send_each_cycle && have_last_sent_ &&
      std::memcmp(&f, &last_sent_, sizeof f) == 0) {
    return IoResult::ok();
  }
  // Until the frame is on the bus the device holds what it last received.
  stats_.output_confirmed = false;
  switch (channel_.send(f, settings_.fd)) {
    case TxStatus::sent:
      // Sent on the bus (a CAN frame is ACKed by the bus, not by the application): the best
      // confirmation CAN offers.
      stats_.output_v = volts;
      stats_.output_confirmed = true;
      ++stats_.writes;
      tx_full_in_a_row_ = 0;
      last_sent_ = f;
      have_last_sent_ = true;
      return IoResult::ok();
    case TxStatus::queue_full:
      ++counters_.tx_queue_full;
      // A single full queue is a transient of a busy bus; a run of them means nobody ACKs.
      if (++tx_full_in_a_row_ >= settings_.tx_full_fault_after) {
        ++stats_.write_errors;
        return IoResult::fail(tx_full_reason_);
      }
      return IoResult::ok();
    case TxStatus::down:
      link_down_ = true;
      ++stats_.write_errors;
      return IoResult::fail(down_reason_);
    case TxStatus::error:
      break;
  }
  ++stats_.write_errors;
  return IoResult::fail(io_failure("send"));
}

// In words, on the loop thread: strerrordesc_np returns glibc's static text and is thread-safe,
// where strerror formats an unknown errno into a shared buffer.
const char* CanDriver::io_failure(const char* operation) noexcept {
  const char* what = strerrordesc_np(channel_.last_errno());
  std::snprintf(io_reason_, sizeof io_reason_, "CAN %s failed on %s: %s", operation,
                settings_.interface.c_str(), what != nullptr ? what : "unknown error");
  return io_reason_;
}

void CanDriver::send_heartbeat_if_due() noexcept {
  if (!heartbeat_due_ || !channel_.valid()) return;
  heartbeat_due_ = false;
  const CanHeartbeat& hb = settings_.heartbeat;
  canfd_frame f{};
  f.can_id = hb.extended ? (hb.frame_id | CAN_EFF_FLAG) : hb.frame_id;
  f.len = 1;  // CANopen heartbeat: DLC 1
  // 0x05: NMT "operational", the state a CANopen consumer expects of a live producer.
  f.data[0] = hb.payload == HeartbeatPayload::canopen ? std::uint8_t{0x05} : heartbeat_counter_++;
  // A refused heartbeat is not a fault by itself: the command frame on the same channel reports
  // a full queue or a link down; a missing heartbeat is the DAQ's to judge.
  if (channel_.send(f, false) == TxStatus::sent) {
    ++counters_.heartbeats;
  } else {
    ++counters_.heartbeat_failures;
  }
}

IoResult CanDriver::write_voltage(double volts) noexcept {
  if (!std::isfinite(volts)) {
    ++stats_.write_errors;
    return IoResult::fail("CAN command: non-finite voltage refused");
  }
  if (!channel_.valid()) {
    ++stats_.write_errors;
    return IoResult::fail("CAN driver not open");
  }
  last_command_ = volts;
  const IoResult r = send_command(volts, false);
  send_heartbeat_if_due();
  return r;
}

void CanDriver::safe_state() noexcept {
  last_command_ = 0.0;
  if (channel_.valid()) {
    (void)send_command(0.0, true);
    send_heartbeat_if_due();
  } else if (stats_.output_v != 0.0) {
    stats_.output_confirmed = false;  // nothing to send 0 V on
  }
}

void CanDriver::close() noexcept {
  safe_state();
  channel_.close();
  have_channel_ = false;
}

DriverStats CanDriver::stats() const noexcept {
  DriverStats s = stats_;
  s.dropped = counters_.unexpected_frames + counters_.kernel_drops;
  s.link_up = channel_.valid() && !bus_off_ && !link_down_;
  return s;
}

}  // namespace scp::drivers::can

#include "drivers/can/can_sim_node.hpp"

#include <time.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <exception>
#include <utility>

#include "drivers/can/signal_codec.hpp"

namespace scp::drivers::can {
namespace {

const CanSettings& validated(const CanSettings& s) {
  if (auto problem = validate_can_settings(s)) {
    throw DriverError("can." + problem->key + ": " + problem->message);
  }
  return s;
}

canid_t wire_id(const CanSignal& sig) noexcept {
  return sig.extended ? (sig.frame_id | CAN_EFF_FLAG) : sig.frame_id;
}

}  // namespace

CanSimNode::CanSimNode(const CanSettings& can, const sim::SimSettings& sim, CanChannel channel)
    : can_(validated(can)), sim_(sim), channel_(std::move(channel)) {
  for (int i = 0; i < 4; ++i) {
    const CanSignal& sig = *signal_at(can_, i);
    if (!sig.present) continue;
    Frame* target = nullptr;
    for (Frame& f : frames_) {
      if (f.frame.can_id == wire_id(sig)) target = &f;
    }
    if (target == nullptr) {
      frames_.emplace_back();
      target = &frames_.back();
      target->frame.can_id = wire_id(sig);
      target->frame.len = static_cast<std::uint8_t>(sig.dlc);
    }
    target->signals[static_cast<std::size_t>(target->n_signals++)] = i;
  }
  sim_.open();
}

bool CanSimNode::send_raw(const canfd_frame& f, bool is_fd) noexcept {
  return channel_.send(f, is_fd) == TxStatus::sent;
}

void CanSimNode::step(double t, double period) noexcept {
  const CanSignal& cmd = can_.command.signal;
  for (int n = 0; n < can_.max_frames_per_cycle; ++n) {
    canfd_frame f{};
    bool is_fd = false;
    const RxStatus rx = channel_.receive(f, is_fd);
    if (rx == RxStatus::empty || rx == RxStatus::down || rx == RxStatus::error) break;
    if (rx != RxStatus::frame || f.can_id != wire_id(cmd) || !signal_fits(cmd, f.len)) {
      ++counters_.ignored;
      continue;
    }
    const double v = decode_signal(cmd, f.data, f.len);
    if (std::isfinite(v)) {
      voltage_ = v;  // the latest command wins, as on a DAC register
      ++counters_.commands;
    }
  }
  (void)sim_.write_voltage(voltage_);
  Sample s;
  const IoResult r = sim_.read(CycleTime{t, period}, s);
  if (r.status != IoStatus::ok) {
    // The simulation's injected faults (read_error, no_data) look like a silent node on CAN.
    ++counters_.sim_errors;
    return;
  }
  if (silent_) return;
  const double values[4] = {s.x, s.xdot, s.temperature, s.voltage};
  for (Frame& fr : frames_) {
    for (int k = 0; k < fr.n_signals; ++k) {
      const int i = fr.signals[static_cast<std::size_t>(k)];
      // A non-finite value (an injected NaN fault) is sent as the all-ones pattern, as a DAQ
      // marks "not available".
      if (!encode_signal(*signal_at(can_, i), values[i], fr.frame.data, fr.frame.len)) {
        (void)insert_raw(*signal_at(can_, i), ~std::uint64_t{0}, fr.frame.data, fr.frame.len);
      }
    }
    if (channel_.send(fr.frame, can_.fd) == TxStatus::sent) {
      ++counters_.frames_sent;
    } else {
      ++counters_.send_failures;
    }
  }
}

int run_can_sim_node(const CanSettings& can, const sim::SimSettings& sim, double period_s, int fd,
                     std::atomic<bool>& stop) {
  if (!(period_s > 0.0) || !std::isfinite(period_s)) {
    std::fprintf(stderr, "scp-simdaq: CAN node period must be > 0 s (got %g)\n", period_s);
    return 1;
  }
  try {
    CanChannel channel;
    if (fd >= 0) {
      channel = CanChannel(fd);
    } else {
      const canid_t ids[1] = {wire_id(can.command.signal)};
      channel = open_socketcan(can.interface, ids, can.fd);
    }
    CanSimNode node(can, sim, std::move(channel));
    const auto period_ns = static_cast<long long>(std::llround(period_s * 1e9));
    timespec next{};
    clock_gettime(CLOCK_MONOTONIC, &next);
    for (long long k = 0; !stop.load(std::memory_order_relaxed); ++k) {
      node.step(static_cast<double>(k) * period_s, period_s);
      long long ns = next.tv_nsec + period_ns;
      next.tv_sec += static_cast<time_t>(ns / 1000000000LL);
      next.tv_nsec = static_cast<long>(ns % 1000000000LL);
      while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr) == EINTR) {
        if (stop.load(std::memory_order_relaxed)) break;
      }
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "scp-simdaq: %s\n", e.what());
    return 1;
  }
}

}  // namespace scp::drivers::can

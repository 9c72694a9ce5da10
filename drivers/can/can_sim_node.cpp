#include "drivers/can/can_sim_node.hpp"

#include <linux/can/error.h>
#include <poll.h>
#include <time.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <exception>
#include <memory>
#include <utility>

#include "common/clock.hpp"
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

using clock::monotonic_s;

bool in_window(double t, double after, double duration) noexcept {
  return after >= 0 && t >= after && (duration <= 0 || t < after + duration);
}

canfd_frame error_frame(canid_t cls, std::uint8_t ctrl) noexcept {
  canfd_frame f{};
  f.can_id = CAN_ERR_FLAG | cls;
  f.len = CAN_ERR_DLC;
  f.data[1] = ctrl;
  return f;
}

}  // namespace

CanSimNode::CanSimNode(const CanSettings& can, const sim::SimSettings& sim, CanChannel channel)
    : can_(validated(can)), sim_(sim), channel_(std::move(channel)) {
  for (int i = 0; i < kSignalCount; ++i) {
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
  wall0_ = monotonic_s();
}

bool CanSimNode::send_raw(const canfd_frame& f, bool is_fd) noexcept {
  return channel_.send(f, is_fd) == TxStatus::sent;
}

void CanSimNode::check_watchdog(double wall, long long step) noexcept {
  // Armed by the first feed, as a CANopen consumer starts monitoring at the first heartbeat.
  if (!(watchdog_timeout_s_ > 0.0) || !watchdog_armed_ || watchdog_tripped_) return;
  if (wall - watchdog_fed_ <= watchdog_timeout_s_) return;
  watchdog_tripped_ = true;
  ++counters_.watchdog_trips;
  voltage_ = 0.0;
  if (log_ != nullptr) std::fprintf(log_, "%lld,%.6f,0,watchdog\n", step, wall);
}

void CanSimNode::step(double t, double period) noexcept {
  const CanSignal& cmd = can_.command.signal;
  const CanHeartbeat& hb = can_.heartbeat;
  const canid_t hb_id = hb.extended ? (hb.frame_id | CAN_EFF_FLAG) : hb.frame_id;
  const long long step_k = std::llround(t / period);
  for (int n = 0; n < can_.max_frames_per_cycle; ++n) {
    canfd_frame f{};
    bool is_fd = false;
    const RxStatus rx = channel_.receive(f, is_fd);
    if (rx == RxStatus::empty || rx == RxStatus::down || rx == RxStatus::error) break;
    if (rx == RxStatus::frame && hb.enabled && f.can_id == hb_id) {
      ++counters_.heartbeats;
      watchdog_fed_ = monotonic_s() - wall0_;
      watchdog_armed_ = true;
      watchdog_tripped_ = false;  // fed again: armed again, commands accepted
      continue;
    }
    if (rx != RxStatus::frame || f.can_id != wire_id(cmd) || !signal_fits(cmd, f.len)) {
      ++counters_.ignored;
      continue;
    }
    if (!hb.enabled) {
      watchdog_fed_ = monotonic_s() - wall0_;
      watchdog_armed_ = true;
      watchdog_tripped_ = false;
    }
    if (watchdog_tripped_) {
      ++counters_.ignored_while_tripped;
      continue;
    }
    const double v = decode_signal(cmd, f.data, f.len);
    if (std::isfinite(v)) {
      voltage_ = v;  // the latest command wins, as on a DAC register
      ++counters_.commands;
      if (log_ != nullptr) {
        std::fprintf(log_, "%lld,%.6f,%.9g\n", step_k, monotonic_s() - wall0_, v);
      }
    }
  }
  check_watchdog(monotonic_s() - wall0_, step_k);
  (void)sim_.write_voltage(voltage_);
  Sample s;
  const IoResult r = sim_.read(CycleTime{t, period}, s);
  if (r.status != IoStatus::ok) {
    // The simulation's injected faults (read_error, no_data) look like a silent node on CAN.
    ++counters_.sim_errors;
    return;
  }
  if (silent_) return;
  const double values[kSignalCount] = {s.x, s.xdot, s.temperature, s.voltage, s.current};
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
  CanNodeOptions options;
  options.period_s = period_s;
  options.fd = fd;
  return run_can_sim_node(can, sim, options, stop);
}

namespace {

CanChannel open_node_channel(const CanSettings& can, int fd) {
  if (fd >= 0) return CanChannel(fd);
  const CanHeartbeat& hb = can.heartbeat;
  const canid_t ids[2] = {wire_id(can.command.signal),
                          hb.extended ? (hb.frame_id | CAN_EFF_FLAG) : hb.frame_id};
  return open_socketcan(can.interface, std::span<const canid_t>(ids, hb.enabled ? 2 : 1), can.fd);
}

// The options' fault window, applied before each step at wall time `w`.
class FaultInjector {
 public:
  explicit FaultInjector(const CanNodeOptions& o) : o_(o) {}
  void apply(CanSimNode& node, double w) {
    const bool faulty = in_window(w, o_.fault_after_s, o_.fault_duration_s);
    // A controller in bus-off neither sends nor receives: the sensor frames stop too (and
    // frames still flowing would tell the daemon the controller had restarted).
    if (o_.fault == CanNodeFault::silent || o_.fault == CanNodeFault::bus_off) {
      node.set_silent(faulty);
    }
    if (o_.fault == CanNodeFault::bus_off && faulty != was_faulty_) {
      (void)node.send_raw(
          faulty ? error_frame(CAN_ERR_BUSOFF, 0) : error_frame(CAN_ERR_RESTARTED, 0), false);
    }
    if (o_.fault == CanNodeFault::error_frames && faulty) {
      (void)node.send_raw(error_frame(CAN_ERR_CRTL, CAN_ERR_CRTL_RX_WARNING), false);
    }
    was_faulty_ = faulty;
  }

 private:
  const CanNodeOptions& o_;
  bool was_faulty_ = false;
};

// One step per wake-up by the daemon's frames, the first one by the forced 0 V command of its
// open(). Stepping once before that would put the node a step ahead, and a read that drains the
// queue could then take x from one step and T from the next.
void run_lockstep(CanSimNode& node, const CanNodeOptions& o, FaultInjector& faults, double wall0,
                  std::atomic<bool>& stop) {
  long long k = 0;
  while (!stop.load(std::memory_order_relaxed)) {
    const double w = monotonic_s() - wall0;
    if (o.duration_s > 0 && w >= o.duration_s) break;
    pollfd p{node.fd(), POLLIN, 0};
    const int ready = poll(&p, 1, 100);
    if (ready <= 0) {
      node.check_watchdog(monotonic_s() - wall0, k);  // a dead daemon sends nothing to wait on
      continue;
    }
    if (p.revents & (POLLHUP | POLLERR)) break;  // the daemon closed its end
    faults.apply(node, w);
    node.step(static_cast<double>(k++) * o.period_s, o.period_s);
  }
}

// One step per period, to absolute deadlines.
void run_periodic(CanSimNode& node, const CanNodeOptions& o, FaultInjector& faults, double wall0,
                  std::atomic<bool>& stop) {
  const auto period_ns = std::llround(o.period_s * 1e9);
  std::int64_t next_ns = clock::monotonic_ns();
  for (long long k = 0; !stop.load(std::memory_order_relaxed); ++k) {
    const double w = monotonic_s() - wall0;
    if (o.duration_s > 0 && w >= o.duration_s) break;
    faults.apply(node, w);
    node.step(static_cast<double>(k) * o.period_s, o.period_s);
    next_ns += period_ns;
    const timespec next = clock::to_timespec(next_ns);
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr) == EINTR) {
      if (stop.load(std::memory_order_relaxed)) break;
    }
  }
}

void print_summary(const CanSimNodeCounters& c, double seconds) {
  std::printf(
      "scp-simdaq: CAN node stopped after %.3f s: %llu commands, %llu frames sent, "
      "%llu send failures, %llu heartbeats, %llu watchdog trips\n",
      seconds, static_cast<unsigned long long>(c.commands),
      static_cast<unsigned long long>(c.frames_sent),
      static_cast<unsigned long long>(c.send_failures),
      static_cast<unsigned long long>(c.heartbeats),
      static_cast<unsigned long long>(c.watchdog_trips));
  std::fflush(stdout);
}

struct FileCloser {
  void operator()(std::FILE* f) const noexcept { std::fclose(f); }
};

}  // namespace

int run_can_sim_node(const CanSettings& can, const sim::SimSettings& sim, const CanNodeOptions& o,
                     std::atomic<bool>& stop) {
  if (!(o.period_s > 0.0) || !std::isfinite(o.period_s)) {
    std::fprintf(stderr, "scp-simdaq: CAN node period must be > 0 s (got %g)\n", o.period_s);
    return 1;
  }
  try {
    CanSimNode node(can, sim, open_node_channel(can, o.fd));
    node.set_watchdog(o.watchdog_timeout_s);
    std::unique_ptr<std::FILE, FileCloser> log;
    if (!o.command_log.empty()) {
      log.reset(std::fopen(o.command_log.c_str(), "w"));
      if (!log) {
        std::fprintf(stderr, "scp-simdaq: cannot write the command log %s\n",
                     o.command_log.c_str());
        return 1;
      }
      setvbuf(log.get(), nullptr, _IOLBF, 0);  // a test may SIGKILL us: every line must be on disk
      node.set_command_log(log.get());
    }
    std::printf("scp-simdaq: CAN node on %s, period %g s%s\n",
                o.fd >= 0 ? ("fd " + std::to_string(o.fd)).c_str() : can.interface.c_str(),
                o.period_s, o.lockstep ? ", lock-step" : "");
    std::fflush(stdout);
    const double wall0 = monotonic_s();
    FaultInjector faults(o);
    if (o.lockstep) {
      run_lockstep(node, o, faults, wall0, stop);
    } else {
      run_periodic(node, o, faults, wall0, stop);
    }
    log.reset();
    print_summary(node.counters(), monotonic_s() - wall0);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "scp-simdaq: %s\n", e.what());
    return 1;
  }
}

}  // namespace scp::drivers::can

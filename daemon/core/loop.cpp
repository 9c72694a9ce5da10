#include "daemon/core/loop.hpp"

#include <cmath>
#include <cstdio>
#include <thread>

#include "common/clock.hpp"
#include "estimator/model.hpp"

namespace scp::daemon {

namespace {

template <std::size_t N, class Vec>
std::array<double, N> to_array(const Vec& v) noexcept {
  std::array<double, N> out{};
  for (std::size_t i = 0; i < N; ++i) out[i] = v[static_cast<Eigen::Index>(i)];
  return out;
}

}  // namespace

Loop::Loop(const config::DaemonConfig& config, drivers::Driver& driver,
           rt::Seqlock<PublishedState>& published, CommandRing& commands, RecordRing* record,
           bool block_when_record_full, HandOffRing* handoff)
    : config_(config),
      safety_(config.safety),
      driver_(driver),
      published_(published),
      commands_(commands),
      record_(record),
      block_when_record_full_(block_when_record_full),
      estimator_(config.estimator),
      excitation_(config.excitation.settings),
      velocity_(velocity::VelocitySettings{config.driver.velocity.bandwidth_hz,
                                           config.driver.velocity.damping}),
      physical_known_(config.actuator.mass_kg > 0.0 && config.actuator.resistance_ohm > 0.0),
      excitation_enabled_(config.excitation.enabled),
      handoff_(handoff) {
  set_reason(fault_reason_, "");
  set_reason(waiting_reason_, "");
}

CycleResult Loop::cycle(const drivers::CycleTime& now) noexcept {
  ++cycles_;
  cycle_t_ = now.t;
  take_safety_limits();
  take_excitation();
  handle_commands();

  // 1. Read.
  bool awaiting = false;
  const drivers::IoStatus read = read_sample(now, awaiting);
  if (read == drivers::IoStatus::end_of_data) {
    shutdown();
    publish(now);
    return CycleResult::end_of_data;
  }
  // 2. Safety: limits on the sample and staleness, independent of the estimator.
  check_safety(now, read, awaiting);
  // 3. Estimate.
  drivers::Sample fed;
  const bool feed = estimate(fed);
  // 4. Excitation and 5. the safety clamp: 0 V unless running.
  const double command = state_ == RunState::running && excitation_enabled_
                             ? clamp_voltage(active_excitation_->voltage(now.t), safety_)
                             : 0.0;
  // 6. Write.
  write(command);
  // 7. Publish.
  publish(now);
  if (feed) {
    if (RecordRing* ring = record_ring()) record(fed, *ring);
  }
  return CycleResult::ok;
}

// A reload's limits, from the start of the cycle after its store (one attempt without waiting;
// a torn read waits for the next cycle).
void Loop::take_safety_limits() noexcept {
  if (safety_cell_ == nullptr || safety_cell_->version() == safety_version_) return;
  const std::uint64_t version = safety_cell_->version();
  if (safety_cell_->try_load(safety_)) safety_version_ = version;
}

drivers::IoStatus Loop::read_sample(const drivers::CycleTime& now, bool& awaiting) noexcept {
  drivers::Sample sample;
  const drivers::IoResult read = driver_.read(now, sample);
  sample_fresh_ = false;
  if (read.status == drivers::IoStatus::end_of_data) return read.status;
  driver_ok_ = read.status != drivers::IoStatus::error;
  // Until the device's first fresh reading it is awaited, not faulted: a DAQ absent or slow at
  // start (or still booting) is the ordinary start of a bench. The output is 0 V either way
  // (STARTING); the service bounds the wait with driver.start_timeout_s.
  awaiting = !have_fresh_ && state_ == RunState::starting;
  if (read.status == drivers::IoStatus::error) {
    const char* reason = read.reason[0] ? read.reason : "driver read failed";
    if (awaiting) {
      set_reason(waiting_reason_, reason);
    } else {
      enter_fault(FaultKind::driver, reason);
    }
  } else if (read.status == drivers::IoStatus::ok) {
    if (xdot_ == Xdot::unknown) {
      xdot_ = std::isfinite(sample.xdot) ? Xdot::measured : Xdot::estimated;
    }
    if (current_ == Current::unknown) {
      current_ = std::isnan(sample.current) ? Current::not_measured : Current::measured;
    }
    sample_ = sample;
    sample_fresh_ = true;
    have_fresh_ = true;
    last_fresh_t_ = now.t;
    set_reason(waiting_reason_, "");
  }
  return read.status;
}

void Loop::check_safety(const drivers::CycleTime& now, drivers::IoStatus read,
                        bool awaiting) noexcept {
  if (sample_fresh_) {
    Reason why{};
    sample_valid_ =
        check_sample(sample_, safety_, xdot_ == Xdot::measured, current_ == Current::measured, why);
    // voltage_command_ is still last cycle's command: the one the plant saw up to this reading.
    if (sample_valid_ &&
        !stuck_.update(sample_, now.t, voltage_command_ != 0.0, safety_.stuck_timeout_s, why)) {
      sample_valid_ = false;
    }
    if (!sample_valid_) enter_fault(FaultKind::value, why);
  } else if (awaiting) {
    if (read != drivers::IoStatus::error && now.t > safety_.stale_timeout_s) {
      set_reason(waiting_reason_, "the device sends no data yet");
    }
  } else if (state_ != RunState::fault) {
    const double age = have_fresh_ ? now.t - last_fresh_t_ : now.t;
    if (age > safety_.stale_timeout_s) {
      Reason why{};
      std::snprintf(why.data(), why.size(),
                    "no fresh reading for %.3f s (safety.stale_timeout_s = %.3f s)", age,
                    safety_.stale_timeout_s);
      enter_fault(FaultKind::driver, why);
    }
  }
  try_recover(now);
  if (state_ == RunState::starting && sample_fresh_ && sample_valid_ && driver_ok_) {
    state_ = RunState::running;  // fresh readings arrived: the output may leave 0 V
  }
}

// The estimator rejects non-finite and out-of-range samples by itself. It learns only while
// running: a faulted bench at 0 V only cools, which excites nothing, and with forgetting θ̂ would
// drift along the unexcited directions (docs/numerics.md, "A latched fault"). θ̂ and R are held;
// the gap restarts the filters on resumption. True when `fed` went to the estimator.
bool Loop::estimate(drivers::Sample& fed) noexcept {
  const bool feed = sample_fresh_ && estimator_input(fed) && state_ == RunState::running;
  if (!feed) {
    if (state_ != RunState::running) handoff_break_ = true;  // nothing to simulate across
    return false;
  }
  // fed.t is when the sample was taken and fed.voltage_since when its voltage took effect, as
  // the driver stamped them (the deadline and −∞ unless it knows better).
  const estimator::Measurement m{fed.t,       fed.x,
                                 fed.xdot,    fed.temperature - config_.actuator.ambient_c,
                                 fed.voltage, fed.voltage_since};
  estimator_.update(m);
  if (cycles_ % kStatePublishCycles == 0) estimator_state_.store(to_view(estimator_.state()));
  hand_off(fed);
  return true;
}

// Sends `command` while running, else 0 V; a failed write faults and 0 V is what counts.
void Loop::write(double command) noexcept {
  if (state_ != RunState::running) {
    driver_.safe_state();
    voltage_command_ = 0.0;
    return;
  }
  const drivers::IoResult written = driver_.write_voltage(command);
  if (written.status == drivers::IoStatus::error) {
    enter_fault(FaultKind::driver, written.reason[0] ? written.reason : "driver write failed");
    command = 0.0;
  }
  voltage_command_ = command;
}

void Loop::take_excitation() noexcept {
  if (excitation_exchange_ == nullptr) return;
  ExcitationUpdate update;
  while (excitation_exchange_->take(update)) {
    if (update.next != nullptr) {
      if (active_excitation_ != &excitation_) excitation_exchange_->retire(active_excitation_);
      active_excitation_ = update.next;
    }
    if (update.enabled >= 0) excitation_enabled_ = update.enabled != 0;
  }
}

void Loop::handle_commands() noexcept {
  Command command;
  while (commands_.try_pop(command)) {
    ack_.seq = command.seq;
    ack_.ok = true;
    set_reason(ack_.message, "done");
    switch (command.kind) {
      case CommandKind::reset:
        estimator_.reset();
        velocity_.reset();
        velocity_started_ = false;
        central_difference_.reset();
        handoff_break_ = true;
        set_reason(ack_.message, "estimator restarted from its initial values");
        break;
      case CommandKind::excitation_on:
        excitation_enabled_ = true;
        set_reason(ack_.message, "excitation on");
        break;
      case CommandKind::excitation_off:
        excitation_enabled_ = false;
        set_reason(ack_.message, "excitation off: output held at 0 V");
        break;
      case CommandKind::clear_fault: {
        if (state_ != RunState::fault) {
          set_reason(ack_.message, "no fault to clear");
          break;
        }
        Reason why{};
        if (cause_gone(why)) {
          state_ = RunState::starting;  // 0 V until the next fresh reading
          set_reason(fault_reason_, "");
          set_reason(ack_.message, "fault cleared");
          ++faults_.cleared;
        } else {
          ack_.ok = false;
          // The cause is the more useful half of the message; keep it whole.
          ack_.message = why;
        }
        break;
      }
    }
  }
}

bool Loop::cause_gone(Reason& why) const noexcept {
  if (!driver_ok_) {
    set_reason(why, "the driver still reports errors");
    return false;
  }
  if (!have_fresh_ || !sample_fresh_) {
    set_reason(why, "no fresh reading this cycle");
    return false;
  }
  return check_sample(sample_, safety_, true, current_ == Current::measured, why);
}

void Loop::enter_fault(FaultKind kind, const char* reason) noexcept {
  Reason r{};
  set_reason(r, reason);
  enter_fault(kind, r);
}

void Loop::enter_fault(FaultKind kind, const Reason& reason) noexcept {
  if (state_ == RunState::stopping) return;
  if (state_ != RunState::fault) {
    fault_reason_ = reason;  // keep the first cause
    fault_kind_ = kind;
    ++faults_.count;
    faults_.last_reason = reason;
    faults_.last_t = cycle_t_;
    faults_.last_unix_ns = clock::unix_ns();
  } else if (kind == FaultKind::value && fault_kind_ == FaultKind::driver) {
    fault_reason_ = reason;  // a bad value while the link was down: now it must latch
    fault_kind_ = kind;
  }
  healthy_since_ = -1.0;
  state_ = RunState::fault;
  driver_.safe_state();  // 0 V in the same cycle
  voltage_command_ = 0.0;
}

void Loop::try_recover(const drivers::CycleTime& now) noexcept {
  if (state_ != RunState::fault || fault_kind_ != FaultKind::driver ||
      safety_.recover_after_s <= 0.0) {
    return;
  }
  if (!(sample_fresh_ && sample_valid_ && driver_ok_)) {
    if (!sample_fresh_ && driver_ok_) return;  // a quiet cycle neither helps nor hurts
    healthy_since_ = -1.0;
    return;
  }
  if (healthy_since_ < 0.0) healthy_since_ = now.t;
  if (now.t - healthy_since_ >= safety_.recover_after_s) {
    state_ = RunState::starting;  // the next fresh reading makes it RUNNING
    set_reason(fault_reason_, "");
    healthy_since_ = -1.0;
    ++faults_.recoveries;
  }
}

void Loop::shutdown() noexcept {
  state_ = RunState::stopping;
  driver_.safe_state();
  voltage_command_ = 0.0;
}

void Loop::publish(const drivers::CycleTime& now) noexcept {
  PublishedState out;
  out.state = state_;
  out.fault_reason = fault_reason_;
  out.awaiting_device = !have_fresh_ && state_ == RunState::starting;
  out.waiting_reason = waiting_reason_;
  out.uptime_s = now.t;
  out.period_s = now.period;
  out.excitation_enabled = excitation_enabled_;
  out.voltage_command = voltage_command_;
  out.last_sample = sample_;
  out.loop = stats_;
  out.driver = driver_.stats();
  out.last_ack = ack_;
  out.handoff_dropped = dropped_handoff_;
  out.unix_ns = clock::unix_ns();
  unix_ns_ = out.unix_ns;
  out.recording = record_ring() != nullptr && !block_when_record_full_;
  out.record_dropped = dropped_rows_;
  out.faults = faults_;

  const estimator::Estimate& e = estimator_.estimate();
  EstimateView& v = out.estimate;
  v.t = e.t;
  v.unix_ns = out.unix_ns;
  v.theta_hat = to_array<6>(e.theta_hat);
  v.sigma = to_array<6>(e.sigma);
  v.eps = to_array<2>(e.eps);
  v.af = to_array<2>(e.af);
  v.af_hat = to_array<2>(e.af_hat);
  v.excitation = to_array<2>(e.excitation);
  v.p_max_eig = {e.p_max_eig_mech, e.p_max_eig_thermal};
  v.converged = {e.converged_mech, e.converged_thermal};
  v.updates = e.updates;
  v.skipped = e.skipped_nonfinite + e.skipped_range + e.skipped_time;
  v.has_truth = driver_.true_theta(now.t, v.theta_true);
  if (physical_known_) {
    const estimator::PhysicalParams p = estimator::physical_from_theta(
        e.theta_hat, config_.actuator.mass_kg, config_.actuator.resistance_ohm);
    v.has_physical = true;
    v.physical = {p.b, p.k, p.alpha1, p.alpha2, p.lambda, p.Cth};
  }
  published_.store(out);
}

// What the estimator sees of this cycle's fresh sample: the sample itself when ẋ is measured;
// otherwise with ẋ estimated from x, either delay-matched (central difference: the previous
// sample, one cycle late) or through the causal filtered differentiator.
bool Loop::estimator_input(drivers::Sample& fed) noexcept {
  if (xdot_ == Xdot::measured) {
    fed = sample_;
    return true;
  }
  if (config_.driver.velocity.method == config::VelocityMethod::central_difference) {
    return central_difference_.push(sample_, fed);
  }
  fed = sample_;
  const double dt = velocity_started_ ? sample_.t - last_velocity_t_ : 0.0;
  fed.xdot = velocity_.update(sample_.x, dt);
  last_velocity_t_ = sample_.t;
  velocity_started_ = true;
  return true;
}

// The refinement sees exactly what the estimator was fed, with the instant the sample's voltage
// took effect (−∞ unless the driver stamps its commands: drivers/sample.hpp).
void Loop::hand_off(const drivers::Sample& fed) noexcept {
  if (handoff_ == nullptr) return;
  if (handoff_break_) {
    ++handoff_segment_;
    handoff_break_ = false;
  }
  HandOff h;
  h.sample.t = fed.t;
  h.sample.x = fed.x;
  h.sample.tbar = fed.temperature - config_.actuator.ambient_c;
  h.sample.voltage = fed.voltage;
  h.sample.voltage_since = fed.voltage_since;
  h.sample.current = fed.current;
  h.segment = handoff_segment_;
  if (!handoff_->try_push(h)) {
    ++dropped_handoff_;
    handoff_break_ = true;
  }
}

// The row holds exactly what the estimator was fed, so replaying the file reproduces the run.
void Loop::record(const drivers::Sample& fed, RecordRing& ring) noexcept {
  const estimator::Estimate& e = estimator_.estimate();
  RecordRow row;
  static_cast<drivers::Sample&>(row) = fed;
  row.voltage_command = voltage_command_;
  row.theta_hat = to_array<6>(e.theta_hat);
  row.sigma = to_array<6>(e.sigma);
  row.eps = to_array<2>(e.eps);
  row.af = to_array<2>(e.af);
  row.af_hat = to_array<2>(e.af_hat);
  row.state = static_cast<std::uint8_t>(state_);
  row.unix_ns = unix_ns_;
  row.xdot_measured = xdot_ == Xdot::measured;
  row.dropped_before = dropped_rows_;
  while (!ring.try_push(row)) {
    if (!block_when_record_full_) {
      ++dropped_rows_;
      return;
    }
    std::this_thread::yield();  // batch run: the recorder catches up, no row is lost
  }
}

}  // namespace scp::daemon

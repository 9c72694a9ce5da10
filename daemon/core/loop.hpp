#pragma once
// One cycle of the daemon, the same code in real time and in batch runs:
//   commands → driver read → safety check → estimator update → excitation → safety clamp →
//   driver write → publish.
// The caller owns timing: the real-time runner sleeps to absolute deadlines between cycles, the
// batch runner does not sleep at all. After construction nothing here allocates, locks or logs.

#include <atomic>
#include <memory>

#include "daemon/config/daemon_config.hpp"
#include "daemon/core/commands.hpp"
#include "daemon/core/estimator_state.hpp"
#include "daemon/core/excitation_exchange.hpp"
#include "daemon/core/handoff.hpp"
#include "daemon/core/published_state.hpp"
#include "daemon/core/record_row.hpp"
#include "daemon/core/rt/seqlock.hpp"
#include "daemon/core/rt/spsc_ring.hpp"
#include "daemon/core/safety.hpp"
#include "daemon/core/velocity/central_difference.hpp"
#include "daemon/core/velocity/velocity_estimator.hpp"
#include "drivers/driver.hpp"
#include "estimator/estimator.hpp"
#include "excitation/excitation.hpp"

namespace scp::daemon {

using RecordRing = rt::SpscRing<RecordRow, 16384>;
using EstimatorStateCell = rt::Seqlock<EstimatorStateView>;
// Safety limits changed by a reload (SIGHUP), written by the main thread, read by the loop.
using SafetyCell = rt::Seqlock<config::SafetySettings>;

enum class CycleResult { ok, end_of_data };

class Loop {
 public:
  // `record` may be null. With `block_when_record_full` (batch runs) a full ring makes the cycle
  // wait for the recorder; in real time a full ring drops the row and counts it. `handoff` (may be
  // null) receives every sample fed to the estimator, for the refinement; a full ring drops the
  // sample, counts it and marks a break in the data.
  Loop(const config::DaemonConfig& config, drivers::Driver& driver,
       rt::Seqlock<PublishedState>& published, CommandRing& commands, RecordRing* record,
       bool block_when_record_full, HandOffRing* handoff = nullptr);

  CycleResult cycle(const drivers::CycleTime& now) noexcept;

  // 0 V and STOPPING; every shutdown path calls it (idempotent).
  void shutdown() noexcept;

  // Loop statistics are kept by the runner that owns the timing; they go out with the next
  // snapshot.
  void set_loop_statistics(const LoopStatistics& stats) noexcept { stats_ = stats; }

  // Warm start, before the first cycle. False when the state is unusable (cold start then).
  bool restore(const estimator::State& state) noexcept { return estimator_.restore(state); }
  // Publishes the state before the first cycle (a restored θ̂ included), so that clients that
  // connect before the loop runs see it.
  void publish_initial() noexcept { publish({0.0, config_.loop.period_s}); }

  // Before the first cycle: the loop takes new safety limits from `cell` at the start of every
  // cycle after a store (one non-waiting attempt per cycle; a torn read waits for the next).
  void follow_safety(const SafetyCell* cell) noexcept { safety_cell_ = cell; }
  // Before the first cycle: a new excitation (a reload) is taken from `exchange` at the start of
  // a cycle, the old one given back on it. With follow_recording the rows go to the ring `ring`
  // points to at each cycle (null: no recording), instead of the constructor's: a reload starts
  // and stops the recording. Both are read once per cycle without waiting.
  void follow_excitation(ExcitationExchange* exchange) noexcept { excitation_exchange_ = exchange; }
  void follow_recording(const std::atomic<RecordRing*>* ring) noexcept { record_source_ = ring; }

  RunState state() const noexcept { return state_; }
  const estimator::Estimator& estimator() const noexcept { return estimator_; }
  // Published every kStatePublishCycles for the checkpointer thread.
  const EstimatorStateCell& estimator_state() const noexcept { return estimator_state_; }
  std::uint64_t dropped_record_rows() const noexcept { return dropped_rows_; }
  std::uint64_t dropped_handoff_samples() const noexcept { return dropped_handoff_; }

  static constexpr std::uint64_t kStatePublishCycles = 100;

 private:
  void take_safety_limits() noexcept;
  void take_excitation() noexcept;
  void handle_commands() noexcept;
  // The cycle's steps, in the order cycle() calls them.
  drivers::IoStatus read_sample(const drivers::CycleTime& now, bool& awaiting) noexcept;
  void check_safety(const drivers::CycleTime& now, drivers::IoStatus read, bool awaiting) noexcept;
  bool estimate(drivers::Sample& fed) noexcept;
  void write(double command) noexcept;
  // A driver fault (failed transaction, lost link, stale data) clears by itself once fresh valid
  // readings have flowed for safety.recover_after_s; a value fault (non-finite reading, a limit
  // exceeded) latches until clear-fault.
  enum class FaultKind : std::uint8_t { driver, value };
  void enter_fault(FaultKind kind, const char* reason) noexcept;
  void enter_fault(FaultKind kind, const Reason& reason) noexcept;
  void try_recover(const drivers::CycleTime& now) noexcept;
  void publish(const drivers::CycleTime& now) noexcept;
  void record(const drivers::Sample& fed, RecordRing& ring) noexcept;
  void hand_off(const drivers::Sample& fed) noexcept;
  bool estimator_input(drivers::Sample& fed) noexcept;
  bool cause_gone(Reason& why) const noexcept;
  RecordRing* record_ring() const noexcept {
    return record_source_ != nullptr ? record_source_->load(std::memory_order_acquire) : record_;
  }

  const config::DaemonConfig& config_;
  config::SafetySettings safety_;  // config_.safety, or the last reload's
  const SafetyCell* safety_cell_ = nullptr;
  std::uint64_t safety_version_ = 0;
  drivers::Driver& driver_;
  rt::Seqlock<PublishedState>& published_;
  CommandRing& commands_;
  RecordRing* record_;
  bool block_when_record_full_;

  estimator::Estimator estimator_;
  excitation::Excitation excitation_;  // from the configuration at start
  const excitation::Excitation* active_excitation_ = &excitation_;  // or a reload's
  ExcitationExchange* excitation_exchange_ = nullptr;
  const std::atomic<RecordRing*>* record_source_ = nullptr;
  velocity::VelocityEstimator velocity_;
  velocity::CentralDifference central_difference_;
  // Decided by the first fresh sample: does the device measure ẋ? If it does, a later NaN ẋ is a
  // sensor fault; if not, ẋ is estimated from x (driver.velocity.method).
  enum class Xdot : std::uint8_t { unknown, measured, estimated } xdot_ = Xdot::unknown;
  // The same for the heater's current: once measured, a later NaN is a sensor fault.
  enum class Current : std::uint8_t { unknown, measured, not_measured } current_ = Current::unknown;
  EstimatorStateCell estimator_state_;
  bool physical_known_;

  StuckDetector stuck_;
  RunState state_ = RunState::starting;
  Reason fault_reason_{};
  // Why the device has not delivered its first reading yet ("" once it has, or before a cycle
  // found anything wrong): published while the loop awaits the device in STARTING.
  Reason waiting_reason_{};
  FaultKind fault_kind_ = FaultKind::driver;
  double healthy_since_ = -1.0;  // loop time since which a driver fault's cause has been gone
  bool excitation_enabled_;
  drivers::Sample sample_{};
  bool sample_fresh_ = false;  // this cycle's read delivered a new, valid sample
  bool sample_valid_ = false;  // the last delivered sample passed the safety check
  double last_fresh_t_ = 0.0;  // loop time of the last fresh sample
  bool have_fresh_ = false;
  double last_velocity_t_ = 0.0;
  bool velocity_started_ = false;
  bool driver_ok_ = true;
  double voltage_command_ = 0.0;
  CommandAck ack_{};
  LoopStatistics stats_{};
  std::uint64_t cycles_ = 0;
  std::uint64_t dropped_rows_ = 0;
  HandOffRing* handoff_;
  std::uint64_t handoff_segment_ = 0;
  bool handoff_break_ = false;  // the next handed-off sample starts a new segment
  std::uint64_t dropped_handoff_ = 0;
  double cycle_t_ = 0.0;  // loop time of the cycle in progress (for the fault history)
  FaultHistory faults_{};
  std::int64_t unix_ns_ = 0;  // CLOCK_REALTIME of the last publish
};

}  // namespace scp::daemon

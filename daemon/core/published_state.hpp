#pragma once
// What the loop publishes every cycle through a Seqlock, and what the socket server, the
// checkpointer and the watchdog read. Plain data: no pointers, no std::string, fixed sizes.

#include <array>
#include <cstdint>

#include "common/names.hpp"
#include "drivers/driver.hpp"

namespace scp::daemon {

enum class RunState : std::uint8_t {
  starting,  // waiting for the first fresh readings; output held at 0 V
  running,   // estimator and excitation active
  fault,     // output at 0 V until clear-fault succeeds
  stopping,  // shutdown in progress; output at 0 V
};

// The wire's spelling (docs/protocol.md, STATUS.state), also in batch summaries, recordings and
// the journal.
inline constexpr NameTable<RunState, 4> kRunStateNames{{{RunState::starting, "starting"},
                                                        {RunState::running, "running"},
                                                        {RunState::fault, "fault"},
                                                        {RunState::stopping, "stopping"}}};

constexpr const char* to_string(RunState state) noexcept {
  return name_of(kRunStateNames, state);
}

// Long enough for a driver's reason with its endpoint and remedy (set_reason cuts at a word).
inline constexpr std::size_t kReasonChars = 320;
inline constexpr std::size_t kHistogramBins = 32;

// Wake-up lateness and cycle execution time, kept by the loop thread only.
struct LoopStatistics {
  std::uint64_t cycles = 0;
  std::uint64_t overruns = 0;        // cycles whose work ran past the next deadline
  std::uint64_t missed_periods = 0;  // periods skipped to resynchronise after an overrun
  double lateness_min_us = 0.0;
  double lateness_mean_us = 0.0;
  double lateness_p50_us = 0.0;  // from the histogram
  double lateness_p99_us = 0.0;  // from the histogram
  double lateness_max_us = 0.0;
  double exec_mean_us = 0.0;
  double exec_max_us = 0.0;
  // Heap allocations by the loop thread since its real-time set-up; counted only in the
  // benchmark build (scp-estimatord-alloccount, bench/), where they must stay 0.
  bool allocations_counted = false;
  std::uint64_t allocations = 0;
  // Lateness histogram: bin i counts wake-ups late by [edge(i), edge(i+1)) µs, edges logarithmic
  // (0, 1, 2, 4, ... µs); the last bin is open-ended.
  std::array<std::uint64_t, kHistogramBins> lateness_histogram{};
};

struct EstimateView {
  double t = 0.0;  // s, loop time of the last update
  // CLOCK_REALTIME (ns since 1970, UTC) of the cycle that published this view: aligns the loop's
  // time with the lab's other instruments (rendered as "utc" and "unix_ns").
  std::int64_t unix_ns = 0;
  std::array<double, 6> theta_hat{};
  std::array<double, 6> sigma{};       // per-parameter standard deviation
  std::array<double, 2> eps{};         // prediction error, eq. (20)
  std::array<double, 2> af{};          // filtered signal a_f, eq. (10)
  std::array<double, 2> af_hat{};      // W_f θ̂, eq. (18)
  std::array<double, 2> excitation{};  // per block: mechanical, thermal
  std::array<double, 2> p_max_eig{};   // per block: largest eigenvalue of P, scaled (≤ p_max)
  std::array<bool, 2> converged{};     // per block
  std::uint64_t updates = 0;
  std::uint64_t skipped = 0;  // samples rejected (non-finite or out of range)
  bool has_truth = false;     // simulated driver only
  std::array<double, 6> theta_true{};
  bool has_physical = false;  // when m and R are configured
  // b, k, alpha1, alpha2, lambda, Cth derived from θ̂ with the configured m and R.
  std::array<double, 6> physical{};
};

struct CommandAck {
  std::uint64_t seq = 0;  // the Command::seq this answers
  bool ok = false;
  std::array<char, kReasonChars> message{};
};

// Faults that came and went: the loop counts them, so a fault that recovered between two polls
// (or overnight) is still visible (STATUS fault_count, last_fault).
struct FaultHistory {
  std::uint64_t count = 0;  // entries into FAULT since start
  std::uint64_t recoveries =
      0;                      // driver faults that cleared by themselves (safety.recover_after_s)
  std::uint64_t cleared = 0;  // faults cleared by clear-fault
  std::array<char, kReasonChars> last_reason{};
  double last_t = 0.0;            // loop time of the last entry into FAULT
  std::int64_t last_unix_ns = 0;  // CLOCK_REALTIME of the same
};

struct PublishedState {
  RunState state = RunState::starting;
  std::array<char, kReasonChars> fault_reason{};
  // STARTING before the device's first fresh reading since start: the device is awaited (not a
  // fault), for driver.start_timeout_s at most when set. waiting_reason says why it is not there
  // yet (the driver's reason; "" until a cycle found one).
  bool awaiting_device = true;
  std::array<char, kReasonChars> waiting_reason{};
  double uptime_s = 0.0;
  double period_s = 0.0;
  bool excitation_enabled = true;
  double voltage_command = 0.0;  // V actually sent this cycle (after safety)
  drivers::Sample last_sample{};
  LoopStatistics loop{};
  drivers::DriverStats driver{};
  EstimateView estimate{};
  CommandAck last_ack{};
  std::uint64_t handoff_dropped = 0;  // samples the refinement's hand-off ring had no room for
  std::int64_t unix_ns = 0;           // CLOCK_REALTIME of this snapshot's cycle
  bool recording = false;             // a service-mode recording is on (config `recording`)
  std::uint64_t record_dropped = 0;   // recording rows the ring had no room for
  FaultHistory faults{};
};

}  // namespace scp::daemon

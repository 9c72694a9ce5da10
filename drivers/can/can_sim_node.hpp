#pragma once
// The simulated SCP actuator served as a CAN node, for scp-simdaq --transport can and for tests:
// each period it takes the latest voltage command frame, advances a sim::SimDriver one period and
// sends the sensor frames laid out by the same CanSettings the daemon's driver decodes.

#include <array>
#include <atomic>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "drivers/can/can_channel.hpp"
#include "drivers/can/can_settings.hpp"
#include "drivers/sim/sim_driver.hpp"
#include "drivers/sim/sim_settings.hpp"

namespace scp::drivers::can {

struct CanSimNodeCounters {
  std::uint64_t commands = 0;  // command frames decoded
  std::uint64_t frames_sent = 0;
  std::uint64_t send_failures = 0;  // the daemon is not reading: frames lost
  std::uint64_t ignored = 0;        // frames that were not the command
  std::uint64_t sim_errors = 0;     // read errors injected by the simulation's fault settings
  std::uint64_t heartbeats = 0;     // heartbeat frames received
  std::uint64_t watchdog_trips = 0;
  std::uint64_t ignored_while_tripped = 0;  // commands refused until the heartbeat returns
};

class CanSimNode {
 public:
  // Throws DriverError on invalid settings (CAN or simulation).
  CanSimNode(const CanSettings& can, const sim::SimSettings& sim, CanChannel channel);

  // One period ending at loop time t: apply the command received since the last step (a DAC
  // holds it over the interval), advance the plant to t, send the sensor frames.
  void step(double t, double period) noexcept;

  // Tests: stop sending sensor frames (a silent node) without stopping the plant.
  void set_silent(bool silent) noexcept { silent_ = silent; }
  // Sends a raw frame (tests inject error frames or malformed payloads through the node).
  bool send_raw(const canfd_frame& f, bool is_fd) noexcept;

  // Every decoded command frame is logged as "step,wall_s,volts" (step = round(t / period) of
  // the step that applies it; wall_s since the node was made). nullptr: no log.
  void set_command_log(std::FILE* log) noexcept { log_ = log; }

  // The node's communication watchdog (timeout_s > 0): when nothing feeds it for timeout_s of
  // wall time the output falls to 0 V (logged "step,wall_s,0,watchdog"), and commands are refused
  // until it is fed again, like a CANopen heartbeat consumer whose error behaviour leaves
  // "operational". Fed by the heartbeat frame of can.heartbeat when enabled, else by any
  // command frame.
  void set_watchdog(double timeout_s) noexcept { watchdog_timeout_s_ = timeout_s; }
  // Trips the watchdog if it is due at wall time `wall` (s since the node was made); step()
  // calls it, lock-step waits call it between frames.
  void check_watchdog(double wall, long long step) noexcept;

  int fd() const noexcept { return channel_.fd(); }
  double voltage() const noexcept { return voltage_; }
  const sim::SimDriver& sim() const noexcept { return sim_; }
  const CanSimNodeCounters& counters() const noexcept { return counters_; }

 private:
  struct Frame {
    canfd_frame frame{};
    std::array<int, kSignalCount> signals{};  // indices into kSignalNames
    int n_signals = 0;
  };

  CanSettings can_;
  sim::SimDriver sim_;
  CanChannel channel_;
  std::vector<Frame> frames_;  // built once in the constructor
  double voltage_ = 0.0;
  bool silent_ = false;
  std::FILE* log_ = nullptr;
  double wall0_ = 0.0;
  double watchdog_timeout_s_ = 0.0;
  double watchdog_fed_ = 0.0;  // wall s since wall0_
  bool watchdog_armed_ = false;
  bool watchdog_tripped_ = false;
  CanSimNodeCounters counters_;
};

// What goes wrong in the fault window of CanNodeOptions.
enum class CanNodeFault : std::uint8_t {
  silent,        // no sensor frames (a node that stopped sending)
  bus_off,       // CAN_ERR_BUSOFF at the start, then silent, CAN_ERR_RESTARTED at the end
  error_frames,  // one CAN_ERR_CRTL (error warning) frame per period: counted, not a fault
};

struct CanNodeOptions {
  double period_s = 0.001;
  int fd = -1;            // ≥ 0: an inherited descriptor (see inherited_fd); else can.interface
  bool lockstep = false;  // one step per received command frame instead of per period
  std::string command_log;
  double fault_after_s = -1.0;  // wall seconds; < 0: no fault
  double fault_duration_s = -1.0;
  CanNodeFault fault = CanNodeFault::silent;
  double duration_s = 0.0;          // > 0: stop after this long
  double watchdog_timeout_s = 0.0;  // > 0: the node's communication watchdog (set_watchdog)
};

// Serves the node in real time until `stop` becomes true: one step per period_s on absolute
// deadlines (CLOCK_MONOTONIC). fd ≥ 0: an inherited descriptor carrying can_frame records (taken
// over and closed on return); fd < 0: a CAN_RAW socket on can.interface. Returns 0 on a clean
// stop, 1 on an error (message on stderr).
int run_can_sim_node(const CanSettings& can, const sim::SimSettings& sim, double period_s, int fd,
                     std::atomic<bool>& stop);
// The same with lock-step, a command log and fault injection (scp-simdaq --transport can).
// Lock-step: the node sends the frames of step 0 at once, then advances one period each time
// command frames arrive, and sends the next frames.
int run_can_sim_node(const CanSettings& can, const sim::SimSettings& sim,
                     const CanNodeOptions& options, std::atomic<bool>& stop);

}  // namespace scp::drivers::can

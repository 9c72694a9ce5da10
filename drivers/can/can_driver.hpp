#pragma once
// The SocketCAN driver: sensor values arrive as DBC-described signals in periodic frames sent by
// the DAQ node; the voltage command leaves in one frame per cycle.
//
// read() drains every pending frame (bounded by max_frames_per_cycle), keeps each signal's latest
// value and the loop time it arrived, and returns:
//   ok       when at least one sensor signal is new this cycle and every present signal is younger
//            than its stale_timeout_s (older values are held, sample-and-hold);
//   no_data  when nothing new arrived but every signal is still within its timeout;
//   error    "CAN signal x stale ..." once a signal is older than its timeout (or never came),
//            "CAN bus-off ..." while the controller is bus-off, "CAN interface down ..." on
//            ENETDOWN.
// Values are reported as decoded, even absurd ones (an all-ones "not available" pattern): the
// loop's safety check judges ranges, not the driver.

#include <linux/can.h>

#include <array>
#include <cstdint>
#include <span>

#include "drivers/can/can_channel.hpp"
#include "drivers/can/can_settings.hpp"
#include "drivers/driver.hpp"

namespace scp::drivers::can {

// CAN-specific counters beyond DriverStats.
struct CanCounters {
  std::uint64_t frames = 0;               // sensor frames used
  std::uint64_t error_frames = 0;         // CAN_ERR_FLAG frames of any class
  std::uint64_t bus_off = 0;              // CAN_ERR_BUSOFF events
  std::uint64_t restarts = 0;             // CAN_ERR_RESTARTED, or frames resuming after bus-off
  std::uint64_t controller_problems = 0;  // CAN_ERR_CRTL (warning/passive/overflow)
  std::uint64_t other_errors = 0;         // lost arbitration, protocol, transceiver, no ACK, ...
  std::uint64_t unexpected_frames = 0;    // ids not in use, RTR, too short for their signals
  std::uint64_t kernel_drops = 0;         // SO_RXQ_OVFL
  std::uint64_t tx_queue_full = 0;        // EAGAIN/ENOBUFS on send
  std::uint64_t heartbeats = 0;           // heartbeat frames sent
  std::uint64_t heartbeat_failures = 0;   // heartbeat frames the channel refused
};

class CanDriver final : public Driver {
 public:
  // Validates the settings (throws DriverError naming the key); open() creates the socket.
  explicit CanDriver(const CanSettings& settings);
  // Uses an already open channel (a socketpair in tests, an fd inherited from a supervisor)
  // instead of creating a socket in open().
  CanDriver(const CanSettings& settings, CanChannel channel);

  std::string_view name() const noexcept override { return "can"; }
  void open() override;
  IoResult read(const CycleTime& now, Sample& out) noexcept override;
  IoResult write_voltage(double volts) noexcept override;
  void safe_state() noexcept override;
  void close() noexcept override;
  DriverStats stats() const noexcept override;

  const CanCounters& counters() const noexcept { return counters_; }
  // The CAN ids the driver receives (with CAN_EFF_FLAG for 29-bit ones), for the socket filter.
  std::span<const canid_t> receive_ids() const noexcept { return {ids_.data(), n_ids_}; }

 private:
  bool all_present_fresh() const noexcept;
  void handle_error_frame(const canfd_frame& f) noexcept;
  void handle_data_frame(const canfd_frame& f, double t) noexcept;
  IoResult send_command(double volts, bool force) noexcept;
  void send_heartbeat_if_due() noexcept;

  CanSettings settings_;
  CanChannel channel_;
  bool have_channel_ = false;

  std::array<canid_t, kSignalCount> ids_{};
  std::size_t n_ids_ = 0;
  std::array<double, kSignalCount> value_{};
  std::array<double, kSignalCount> rx_t_{};  // loop time the value arrived
  std::array<bool, kSignalCount> received_{};
  std::array<bool, kSignalCount> fresh_{};  // arrived during this read
  std::array<std::array<char, 112>, kSignalCount> stale_reason_{};
  std::array<std::array<char, 112>, kSignalCount> never_reason_{};
  char bus_off_reason_[160] = {};
  char down_reason_[160] = {};
  char tx_full_reason_[160] = {};
  char io_reason_[160] = {};  // the last failed receive or send, with the channel's errno
  const char* io_failure(const char* operation) noexcept;

  bool started_ = false;
  double start_t_ = 0.0;
  bool bus_off_ = false;
  bool link_down_ = false;
  double last_command_ = 0.0;
  int tx_full_in_a_row_ = 0;
  bool have_last_sent_ = false;
  canfd_frame last_sent_{};
  // Heartbeat: read() marks it due from the loop time (so only a loop that keeps cycling feeds
  // the DAQ's watchdog), the write phase sends it after the command frame.
  bool heartbeat_due_ = false;
  double next_heartbeat_t_ = 0.0;
  std::uint8_t heartbeat_counter_ = 0;
  DriverStats stats_;
  CanCounters counters_;
};

}  // namespace scp::drivers::can

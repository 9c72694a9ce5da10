#pragma once
// A DAQ speaking Modbus TCP or RTU (libmodbus) behind the driver contract.
//
// Threads: the loop thread alone uses the active link (modbus_link.hpp) in read/write/safe_state.
// A lost link is handed to a reconnect thread owned by the driver, which destroys the dead link,
// opens a new one with exponential back-off (connect, 0 V, a probe read) and publishes it through
// an atomic pointer; the loop adopts it at its next call. The loop never connects, never sleeps
// and never takes a lock the reconnect thread holds.

#include <array>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "drivers/driver.hpp"
#include "drivers/modbus/modbus_link.hpp"
#include "drivers/modbus/modbus_settings.hpp"
#include "drivers/modbus/read_plan.hpp"
#include "drivers/modbus/stamp_gate.hpp"

namespace scp::drivers::modbus {

class ModbusDriver final : public Driver {
 public:
  // `period_s`: the loop period, checked against the response timeout at open().
  ModbusDriver(ModbusSettings settings, double period_s);
  ~ModbusDriver() override;

  std::string_view name() const noexcept override { return "modbus"; }
  // Checks timing, connects, writes 0 V and starts the reconnect thread. Throws DriverError
  // naming the remedy for what waiting cannot fix (impossible timing, serial permission, an
  // exception reply to the 0 V command). A DAQ that does not answer yet (unreachable, refusing,
  // silent) is treated like a link lost later: open() returns with the link down and the
  // reconnect thread keeps trying with back-off; reads report why until it answers. In an
  // offline run (enforce_period_budget false) it throws instead.
  void open() override;
  // One transaction per read block. A failed transaction returns no_data (with a reason) while at
  // most max_consecutive_failures reads in a row have failed, then IoStatus::error. NaN, inf and
  // out-of-range values are passed on: the loop's safety layer judges them.
  IoResult read(const CycleTime& now, Sample& out) noexcept override;
  // Same tolerance as read() for failed writes. Until the first successful read after a
  // reconnection the DAQ is sent 0 V whatever is asked. A non-finite value or one outside
  // driver.modbus.command.min/max writes 0 V and fails.
  IoResult write_voltage(double volts) noexcept override;
  void safe_state() noexcept override;
  void close() noexcept override;
  DriverStats stats() const noexcept override;

  const ReadPlan& plan() const noexcept { return plan_; }
  double last_command() const noexcept { return last_command_; }
  // Non-real-time: why the reconnect thread's last attempt failed ("" after a success).
  std::string background_error() const override;

 private:
  // Reasons for one transaction, built once at open() so read/write hand out stable strings:
  // [0] unclassified, [1..11] exception codes, then the named causes below. `dropped` holds the
  // same texts for a failure that cost the link.
  enum Reason : std::size_t {
    kOther = 0,
    kTimeout = 12,
    kLinkLost = 13,
    kCrc = 14,
    kBadData = 15,
    kBadSlave = 16,
    kLineBusy = 17,
    kReasonCount = 18
  };
  struct Reasons {
    std::array<std::string, kReasonCount> why;
    std::array<std::string, kReasonCount> dropped;
  };
  static Reasons make_reasons(const std::string& what, int max_failures);
  static std::size_t reason_index(int err) noexcept;

  // open()'s halves: what the settings decide (plan, reasons, wire model), then the first link.
  void prepare();
  void connect_first();
  // The command registers' write on `link` (any thread; touches no loop state): 0 or an
  // errno-style code.
  int write_command_registers(ModbusLink& link, const std::uint16_t* registers) const noexcept;
  int write_zero(ModbusLink& link) const noexcept;
  void reconnect_main(std::uint64_t attempts_so_far);
  // One reconnection attempt: a link with 0 V written and a probe read done, or nullptr and why.
  std::unique_ptr<ModbusLink> try_link(std::string& error) const;
  void adopt_fresh_link() noexcept;
  // A failure that makes the link untrustworthy: the next write-type call tries 0 V on it, then
  // hands it to the reconnect thread (drop_link).
  void doom_link(const char* reason) noexcept;
  void drop_link() noexcept;
  // Classifies a failed transaction, updates the streaks and returns the reason to report.
  const char* transaction_failed(const Reasons& reasons, int err) noexcept;
  IoResult tolerate(int& streak, const char* reason) noexcept;
  bool write_command(double volts, int& err) noexcept;
  // Every watchdog_every-th call (one per cycle, from write_voltage or safe_state) toggles the
  // heartbeat register.
  void feed_watchdog() noexcept;
  // Loop time of a CLOCK_MONOTONIC instant, on the clock of the last read's CycleTime.
  double loop_time(std::int64_t monotonic_ns) const noexcept;
  bool stamping() const noexcept { return settings_.timing.stamp && deadline_ns_ != 0; }
  std::string endpoint() const;
  int write_function() const noexcept;

  ModbusSettings settings_;
  double period_s_;
  ReadPlan plan_;
  std::vector<std::array<std::uint16_t, kMaxRegistersPerRead>> buffers_;
  std::vector<Reasons> read_reasons_;  // one per read block
  Reasons write_reasons_;
  Reasons heartbeat_reasons_;
  int heartbeat_cycle_ = 0;
  std::uint16_t heartbeat_value_ = 0;
  std::string start_reason_;  // link never up yet

  // Loop thread only.
  std::unique_ptr<ModbusLink> link_;
  std::uint64_t late_before_link_ = 0;  // late replies counted on the links before link_
  bool doomed_ = false;                 // link_ failed in a way that costs the link (see doom_link)
  const char* down_reason_ = "";        // why there is no link, for the fault reason
  int read_streak_ = 0;
  int write_streak_ = 0;
  int timeout_streak_ = 0;
  bool need_fresh_reading_ = false;
  double last_command_ = 0.0;
  // Time stamps (settings_.timing): the last read's deadline on both clocks, the wire model's
  // offsets and when last_command_ took effect (loop time; −∞ while unknown).
  std::int64_t deadline_ns_ = 0;
  double deadline_t_ = 0.0;
  std::size_t x_block_ = 0;
  double read_event_s_ = 0.0;   // sample instant − read midpoint, input latency included
  double write_event_s_ = 0.0;  // command effect − write midpoint, output latency included
  double voltage_since_ = -std::numeric_limits<double>::infinity();
  // A TCP-to-RTU gateway's line (timing.serial_line): when the last transaction's reply was
  // complete. A request sent sooner than 3.5 characters after it waits on the gateway's line, so
  // the slave sees it start then, not when the driver sent it. (On an RTU port the driver keeps
  // that silence itself before sending: ModbusLink.)
  std::int64_t line_free_ns_ = 0;
  std::int64_t gap_ns_ = 0;
  std::int64_t cycle_budget_ns_ = 0;  // what a cycle's transactions share: the loop period
  std::int64_t safe_budget_ns_ = 0;   // what safe_state()'s 0 V gets, whenever it is called
  // The last transaction's bounds on the line: from when its request left (the link's clock,
  // or `called_ns` if it never did) to when its reply arrived (the link's, or now), the begin
  // moved to when a gateway's line could carry it.
  struct Span {
    std::int64_t begin_ns;
    std::int64_t end_ns;
  };
  Span last_span(std::int64_t called_ns) const noexcept;
  // The stamp of the transaction just made: its span's midpoint, or the gate's estimate when
  // it took far longer than usual (counted in stats_.stretched_stamps), for reads and writes
  // alike: with the replies' kernel stamps, what stretches is the reply, after the device acted.
  std::int64_t transaction_stamp(std::int64_t called_ns, StampGate& gate) noexcept;
  void mark_line_busy(std::int64_t end_ns) noexcept;
  // When the line saw a request sent at begin_ns start: not before the previous frame's gap.
  std::int64_t line_begin_ns(std::int64_t begin_ns, std::int64_t end_ns) const noexcept;
  StampGate read_gate_;
  StampGate write_gate_;
  DriverStats stats_;
  bool opened_ = false;

  // Hand-over between the loop thread and the reconnect thread (owning pointers).
  std::atomic<ModbusLink*> fresh_{nullptr};    // connected, 0 V written and probed, for the loop
  std::atomic<ModbusLink*> retired_{nullptr};  // dropped by the loop, for the thread to destroy
  std::atomic<bool> link_wanted_{false};
  std::atomic<bool> stop_{false};
  mutable std::mutex sleep_mutex_;  // reconnect thread and non-real-time callers only
  std::condition_variable sleep_cv_;
  std::string connect_error_;  // guarded by sleep_mutex_
  std::thread reconnector_;
};

}  // namespace scp::drivers::modbus

#pragma once
// A DAQ speaking Modbus TCP or RTU (libmodbus) behind the driver contract.
//
// Threads: the loop thread alone uses the active libmodbus context in read/write/safe_state. A
// lost link is handed to a reconnect thread owned by the driver, which closes the dead context,
// opens a new one with exponential back-off (modbus_connect, a probe read) and publishes it
// through an atomic pointer; the loop adopts it at its next call. The loop never connects, never
// sleeps and never takes a lock the reconnect thread holds.

#include <array>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "drivers/driver.hpp"
#include "drivers/modbus/modbus_settings.hpp"
#include "drivers/modbus/read_plan.hpp"

struct _modbus;  // libmodbus' modbus_t, kept out of this header

namespace scp::drivers::modbus {

class ModbusDriver final : public Driver {
 public:
  // `period_s`: the loop period, checked against the response timeout at open().
  ModbusDriver(ModbusSettings settings, double period_s);
  ~ModbusDriver() override;

  std::string_view name() const noexcept override { return "modbus"; }
  // Checks timing, connects, writes 0 V and starts the reconnect thread. Throws DriverError
  // naming the remedy (unreachable host, serial permission, exception reply to the command...).
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
  DriverStats stats() const noexcept override { return stats_; }

  const ReadPlan& plan() const noexcept { return plan_; }
  double last_command() const noexcept { return last_command_; }

 private:
  // Reasons for one transaction, built once at open() so read/write hand out stable strings.
  enum Reason : std::size_t { kOther = 0, kTimeout = 12, kLinkLost = 13, kReasonCount = 14 };
  using Reasons = std::array<std::string, kReasonCount>;

  _modbus* make_context(std::string& error) const;
  bool probe(_modbus* ctx);
  void reconnect_main();
  void adopt_fresh_link() noexcept;
  void drop_link() noexcept;
  // Classifies errno after a failed transaction and returns the reason to report.
  const char* transaction_failed(const Reasons& reasons, int err) noexcept;
  IoResult tolerate(int& streak, const char* reason) noexcept;
  bool write_command(double volts, int& err) noexcept;
  std::string endpoint() const;

  ModbusSettings settings_;
  double period_s_;
  ReadPlan plan_;
  std::vector<std::array<std::uint16_t, kMaxRegistersPerRead>> buffers_;
  std::vector<Reasons> read_reasons_;  // one per read block
  Reasons write_reasons_;

  // Loop thread only.
  _modbus* ctx_ = nullptr;
  int read_streak_ = 0;
  int write_streak_ = 0;
  int timeout_streak_ = 0;
  bool need_fresh_reading_ = false;
  double last_command_ = 0.0;
  DriverStats stats_;
  bool opened_ = false;

  // Hand-over between the loop thread and the reconnect thread.
  std::atomic<_modbus*> fresh_{nullptr};    // connected and probed, for the loop to adopt
  std::atomic<_modbus*> retired_{nullptr};  // dropped by the loop, for the thread to free
  std::atomic<bool> link_wanted_{false};
  std::atomic<bool> stop_{false};
  std::mutex sleep_mutex_;  // reconnect thread and close() only
  std::condition_variable sleep_cv_;
  std::thread reconnector_;
};

}  // namespace scp::drivers::modbus

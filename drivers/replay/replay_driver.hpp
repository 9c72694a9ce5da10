#pragma once
// Replays a Trace through the driver contract, one row per read(), so a recorded run can be
// re-estimated offline with exactly the loop the daemon runs live.

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "drivers/driver.hpp"
#include "drivers/replay/csv_trace.hpp"

namespace scp::drivers::replay {

class ReplayDriver final : public Driver {
 public:
  // Throws DriverError if the trace has fewer than 2 rows or no valid period.
  explicit ReplayDriver(Trace trace);
  // Loads the CSV; a TraceError is rethrown as DriverError with the same message.
  explicit ReplayDriver(const std::string& path);

  std::string_view name() const noexcept override { return "replay"; }
  // Rewinds to the first row.
  void open() override;
  // The next row, its t re-based so that row 0 is at t = 0 (the file's differences are kept);
  // IoStatus::end_of_data after the last row. `now` is not used: the file sets the pace.
  IoResult read(const CycleTime& now, Sample& out) noexcept override;
  // A recording cannot be actuated: commands are only counted.
  IoResult write_voltage(double volts) noexcept override;
  void safe_state() noexcept override { ++safe_states_; }
  void close() noexcept override {}
  DriverStats stats() const noexcept override { return stats_; }

  double period() const noexcept { return trace_.period; }
  std::size_t size() const noexcept { return trace_.rows.size(); }
  std::size_t position() const noexcept { return next_; }  // rows already returned
  std::uint64_t safe_states() const noexcept { return safe_states_; }
  const Trace& trace() const noexcept { return trace_; }

 private:
  Trace trace_;
  std::size_t next_ = 0;
  std::uint64_t safe_states_ = 0;
  DriverStats stats_;
};

}  // namespace scp::drivers::replay

#pragma once
// Replays a Trace through the driver contract, one row per read(), so a recorded run can be
// re-estimated offline with exactly the loop the daemon runs live.

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "drivers/driver.hpp"
#include "drivers/replay/csv_trace.hpp"

namespace scp::drivers::replay {

class ReplayDriver final : public Driver {
 public:
  // Throws DriverError if the trace has fewer than 2 rows or no valid period.
  explicit ReplayDriver(Trace trace);
  // Loads the CSV; a TraceError is rethrown as DriverError with the same message.
  explicit ReplayDriver(const std::string& path);
  // Files and directories in order (load_traces()): a rotated recording.
  explicit ReplayDriver(const std::vector<std::string>& paths);

  std::string_view name() const noexcept override { return "replay"; }
  // Rewinds to the first row.
  void open() override;
  // The next row, its t as recorded (the live estimator was fed that t: re-basing it would change
  // the steps' rounding and the replay would no longer reproduce the run bit for bit);
  // IoStatus::end_of_data after the last row. `now` is not used: the file sets the pace.
  IoResult read(const CycleTime& now, Sample& out) noexcept override;
  // A recording cannot be actuated: commands are only counted.
  IoResult write_voltage(double volts) noexcept override;
  void safe_state() noexcept override { ++safe_states_; }
  void close() noexcept override {}
  DriverStats stats() const noexcept override { return stats_; }
  bool stamps_voltage_instants() const noexcept override { return trace_.voltage_since_column; }

  double period() const noexcept { return trace_.period; }
  std::size_t size() const noexcept { return trace_.rows.size(); }
  std::size_t position() const noexcept { return next_; }  // rows already returned
  // The time of the row the next read() returns (the batch runner's cycle time); false at the end.
  bool next_time(double& t) const noexcept {
    if (next_ >= trace_.rows.size()) return false;
    t = trace_.rows[next_].t;
    return true;
  }
  std::uint64_t safe_states() const noexcept { return safe_states_; }
  const Trace& trace() const noexcept { return trace_; }

 private:
  Trace trace_;
  std::size_t next_ = 0;
  std::uint64_t safe_states_ = 0;
  DriverStats stats_;
};

}  // namespace scp::drivers::replay

#include "drivers/replay/replay_driver.hpp"

#include <cmath>
#include <utility>

namespace scp::drivers::replay {

namespace {

Trace load_or_throw(const std::vector<std::string>& paths) {
  try {
    return load_traces(paths);
  } catch (const TraceError& e) {
    throw DriverError(e.what());
  }
}

}  // namespace

ReplayDriver::ReplayDriver(Trace trace) : trace_(std::move(trace)) {
  if (trace_.rows.size() < 2) {
    throw DriverError("replay: the trace has " + std::to_string(trace_.rows.size()) +
                      " rows; at least 2 are needed to know the sample period");
  }
  if (!std::isfinite(trace_.period) || trace_.period <= 0.0) {
    throw DriverError("replay: the trace has no valid sample period; load it with load_trace()");
  }
}

ReplayDriver::ReplayDriver(const std::string& path)
    : ReplayDriver(load_or_throw(std::vector<std::string>{path})) {}

ReplayDriver::ReplayDriver(const std::vector<std::string>& paths)
    : ReplayDriver(load_or_throw(paths)) {}

void ReplayDriver::open() {
  next_ = 0;
}

IoResult ReplayDriver::read(const CycleTime& /*now*/, Sample& out) noexcept {
  if (next_ >= trace_.rows.size()) return {IoStatus::end_of_data, "replay: end of trace"};
  ++stats_.reads;
  out = trace_.rows[next_];
  ++next_;
  return IoResult::ok();
}

IoResult ReplayDriver::write_voltage(double /*volts*/) noexcept {
  ++stats_.writes;
  return IoResult::ok();
}

}  // namespace scp::drivers::replay

#include "drivers/modbus/timing.hpp"

#include <cmath>
#include <sstream>

#include "drivers/driver.hpp"
#include "drivers/modbus/read_plan.hpp"

namespace scp::drivers::modbus {

int transactions_per_cycle(const ModbusSettings& settings) {
  // + the command write, + the watchdog heartbeat in the cycles that carry one.
  return static_cast<int>(plan_reads(settings, settings.max_read_gap).blocks.size()) + 1 +
         (settings.watchdog_register >= 0 ? 1 : 0);
}

void check_timing(const ModbusSettings& settings, double period_s) {
  if (!std::isfinite(period_s) || period_s <= 0.0) {
    throw DriverError("modbus: the loop period must be a positive number of seconds");
  }
  const int n = transactions_per_cycle(settings);
  const double worst = settings.response_timeout_s * n;
  if (worst <= period_s) return;
  std::ostringstream out;
  out.precision(4);
  out << "modbus: response timeout " << settings.response_timeout_s * 1e3 << " ms x " << n
      << " transactions per cycle = " << worst * 1e3 << " ms exceeds the " << period_s * 1e3
      << " ms loop period; raise loop.period_s to at least " << worst * 1e3
      << " ms, or lower driver.modbus.response_timeout to at most " << period_s / n * 1e3 << " ms";
  if (n > 2) out << ", or place the signals in adjacent registers so they are read in one request";
  throw DriverError(out.str());
}

}  // namespace scp::drivers::modbus

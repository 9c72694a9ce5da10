#pragma once
// The loop's period budget: every transaction of a cycle may wait up to the response timeout,
// and a cycle must still end before the next deadline even when the DAQ stops answering.

#include "drivers/modbus/modbus_settings.hpp"

namespace scp::drivers::modbus {

// Transactions one loop cycle costs: one per read block plus the voltage command write.
int transactions_per_cycle(const ModbusSettings& settings);

// Throws DriverError with the numbers and the remedies when response_timeout × transactions
// exceeds `period_s`.
void check_timing(const ModbusSettings& settings, double period_s);

}  // namespace scp::drivers::modbus

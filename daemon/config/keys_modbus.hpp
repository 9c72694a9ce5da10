#pragma once
// The YAML keys of the Modbus DAQ driver (section driver.modbus), declared once.

#include "daemon/config/binder.hpp"
#include "drivers/modbus/modbus_settings.hpp"

namespace scp::config {

// Declares every key of driver.modbus on `modbus_section` (the binder returned by
// driver.section("modbus", ...)), fills `out`, and runs the cross-key checks (overlapping
// registers, 32-bit types without word_order, command type and range), failing through
// Binder::fail with the key's line.
void declare_modbus_keys(Binder& modbus_section, drivers::modbus::ModbusSettings& out);

}  // namespace scp::config

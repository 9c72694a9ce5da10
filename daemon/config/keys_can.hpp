#pragma once
// The YAML keys of the SocketCAN driver (section driver.can), declared once.

#include "daemon/config/binder.hpp"
#include "drivers/can/can_settings.hpp"

namespace scp::config {

// Declares every key of driver.can on `can_section` (the binder returned by
// driver.section("can", ...)), fills `out`, and runs the cross-key checks of
// drivers::can::validate_can_settings (ids within 11/29 bits, signals inside their frame, no two
// signals sharing bits, command id distinct from sensor ids), failing through Binder::fail on the
// offending key so the message carries its line.
void declare_can_keys(Binder& can_section, drivers::can::CanSettings& out);

}  // namespace scp::config

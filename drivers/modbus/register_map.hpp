#pragma once
// The register map as a list of named signals, and the one map-level rule both the config layer
// and the driver enforce: no two signals may share a register. Header-only so scp_config can use
// it without linking the driver.

#include <array>
#include <optional>
#include <string_view>
#include <utility>

#include "drivers/modbus/modbus_settings.hpp"
#include "drivers/modbus/register_codec.hpp"

namespace scp::drivers::modbus {

// The signals in a fixed order; the names are the config keys under driver.modbus.signals.
enum class SignalId : std::uint8_t { x, xdot, temperature, voltage, current };
inline constexpr std::size_t kSignalCount = 5;
inline constexpr std::array<std::string_view, kSignalCount> kSignalNames = {
    "x", "xdot", "temperature", "voltage", "current"};

inline std::array<const RegisterSignal*, kSignalCount> signals_of(const ModbusSettings& s) {
  return {&s.x, &s.xdot, &s.temperature, &s.voltage, &s.current};
}

// Registers [first, last] a signal occupies.
struct RegisterSpan {
  std::string_view name;  // "signals.x" or "command"
  Table table;
  int first;
  int last;
};

// The first pair of map entries (read signals and the command register) that share a register,
// by config key, or nothing. A shared register would make one of them silently wrong.
inline std::optional<std::pair<RegisterSpan, RegisterSpan>> find_overlap(const ModbusSettings& s) {
  static constexpr std::array<std::string_view, kSignalCount> kKeys = {
      "signals.x", "signals.xdot", "signals.temperature", "signals.voltage", "signals.current"};
  std::array<RegisterSpan, kSignalCount + 1> spans{};
  std::size_t n = 0;
  const auto sigs = signals_of(s);
  for (std::size_t i = 0; i < kSignalCount; ++i) {
    if (!sigs[i]->present) continue;
    spans[n++] = {kKeys[i], sigs[i]->table, sigs[i]->address,
                  sigs[i]->address + register_count(sigs[i]->type) - 1};
  }
  spans[n++] = {"command", Table::holding, s.command.address,
                s.command.address + register_count(s.command.type) - 1};
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = i + 1; j < n; ++j) {
      if (spans[i].table == spans[j].table && spans[i].first <= spans[j].last &&
          spans[j].first <= spans[i].last) {
        return std::make_pair(spans[i], spans[j]);
      }
    }
  }
  return std::nullopt;
}

}  // namespace scp::drivers::modbus

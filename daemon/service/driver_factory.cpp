#include "daemon/service/driver_factory.hpp"

#include <functional>
#include <utility>

#include "drivers/can/can_driver.hpp"
#include "drivers/modbus/modbus_driver.hpp"
#include "drivers/replay/replay_driver.hpp"
#include "drivers/sim/sim_driver.hpp"

namespace scp::daemon {

namespace {

using Factory = std::function<std::unique_ptr<drivers::Driver>(const config::DaemonConfig&)>;

const std::vector<std::pair<std::string, Factory>>& registry() {
  static const std::vector<std::pair<std::string, Factory>> entries = {
      {"sim",
       [](const config::DaemonConfig& c) {
         return std::make_unique<drivers::sim::SimDriver>(c.driver.sim);
       }},
      {"replay",
       [](const config::DaemonConfig& c) {
         return std::make_unique<drivers::replay::ReplayDriver>(c.driver.replay.file);
       }},
      {"modbus",
       [](const config::DaemonConfig& c) {
         return std::make_unique<drivers::modbus::ModbusDriver>(c.driver.modbus, c.loop.period_s);
       }},
      {"can",
       [](const config::DaemonConfig& c) {
         return std::make_unique<drivers::can::CanDriver>(c.driver.can);
       }},
  };
  return entries;
}

}  // namespace

std::unique_ptr<drivers::Driver> make_driver(const config::DaemonConfig& config) {
  for (const auto& [name, factory] : registry()) {
    if (name == config.driver.type) return factory(config);
  }
  std::string known;
  for (const auto& name : driver_names()) known += (known.empty() ? "" : ", ") + name;
  throw drivers::DriverError("driver.type '" + config.driver.type +
                             "' is not built into this scp-estimatord; available: " + known);
}

std::vector<std::string> driver_names() {
  std::vector<std::string> names;
  for (const auto& entry : registry()) names.push_back(entry.first);
  return names;
}

std::string driver_endpoint(const config::DaemonConfig& config) {
  const auto& d = config.driver;
  if (d.type == "modbus") {
    if (d.modbus.transport == drivers::modbus::Transport::rtu)
      return "modbus rtu " + d.modbus.device + " unit " + std::to_string(d.modbus.unit_id);
    return "modbus tcp " + d.modbus.host + ":" + std::to_string(d.modbus.port) + " unit " +
           std::to_string(d.modbus.unit_id);
  }
  if (d.type == "can") return "can " + d.can.interface;
  if (d.type == "replay") return "replay " + d.replay.file;
  return d.type;
}

}  // namespace scp::daemon

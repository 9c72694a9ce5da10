#include "daemon/service/driver_factory.hpp"

#include "drivers/can/can_driver.hpp"
#include "drivers/modbus/modbus_driver.hpp"
#include "drivers/replay/replay_driver.hpp"
#include "drivers/sim/sim_driver.hpp"

namespace scp::daemon {

std::unique_ptr<drivers::Driver> make_driver(const config::DaemonConfig& config) {
  const auto& d = config.driver;
  switch (d.type) {
    case config::DriverType::sim:
      return std::make_unique<drivers::sim::SimDriver>(d.sim);
    case config::DriverType::replay:
      return std::make_unique<drivers::replay::ReplayDriver>(d.replay.file);
    case config::DriverType::modbus:
      return std::make_unique<drivers::modbus::ModbusDriver>(d.modbus, config.loop.period_s);
    case config::DriverType::can:
      return std::make_unique<drivers::can::CanDriver>(d.can);
  }
  throw drivers::DriverError(std::string("driver.type '") + config::to_string(d.type) +
                             "' has no driver in this scp-estimatord");
}

std::string driver_endpoint(const config::DaemonConfig& config) {
  const auto& d = config.driver;
  switch (d.type) {
    case config::DriverType::modbus:
      if (d.modbus.transport == drivers::modbus::Transport::rtu)
        return "modbus rtu " + d.modbus.device + " unit " + std::to_string(d.modbus.unit_id);
      return "modbus tcp " + d.modbus.host + ":" + std::to_string(d.modbus.port) + " unit " +
             std::to_string(d.modbus.unit_id);
    case config::DriverType::can:
      return "can " + d.can.interface;
    case config::DriverType::replay:
      return "replay " + d.replay.file;
    case config::DriverType::sim:
      break;
  }
  return config::to_string(d.type);
}

}  // namespace scp::daemon

// driver.modbus keys read through the lead's Binder: values land in ModbusSettings, and each
// mistake names the key, the line and the fix.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <string>

#include "daemon/config/binder.hpp"
#include "daemon/config/keys_modbus.hpp"
#include "tests/support/config_section.hpp"

namespace scp::config {
namespace {

using drivers::modbus::ModbusSettings;

ModbusSettings load(const std::string& yaml) {
  return test::load_section<ModbusSettings>(yaml, "modbus", declare_modbus_keys);
}

std::string error_of(const std::string& yaml) {
  return test::section_error<ModbusSettings>(yaml, "modbus", declare_modbus_keys, "(no error)");
}

TEST(ModbusKeys, FullMapIsRead) {
  const ModbusSettings s = load(R"(modbus:
  transport: rtu
  rtu: {device: /dev/ttyS3, baud: 19200, parity: E, data_bits: 8, stop_bits: 1}
  unit_id: 7
  response_timeout: 0.02
  max_consecutive_failures: 5
  reconnect: {initial: 0.5, max: 8}
  signals:
    x: {table: holding, address: 100, type: int32, word_order: ba, scale: 1.0e-6}
    temperature: {address: 3, type: int16, scale: 0.1, offset: -50}
  command: {address: 200, type: uint16, scale: 0.001, min: 0, max: 10}
)");
  EXPECT_EQ(s.transport, drivers::modbus::Transport::rtu);
  EXPECT_EQ(s.device, "/dev/ttyS3");
  EXPECT_EQ(s.baud, 19200);
  EXPECT_EQ(s.parity, 'E');
  EXPECT_EQ(s.unit_id, 7);
  EXPECT_EQ(s.response_timeout_s, 0.02);
  EXPECT_EQ(s.max_consecutive_failures, 5);
  EXPECT_EQ(s.reconnect_initial_s, 0.5);
  EXPECT_TRUE(s.x.present);
  EXPECT_EQ(s.x.table, drivers::modbus::Table::holding);
  EXPECT_EQ(s.x.address, 100);
  EXPECT_EQ(s.x.type, drivers::modbus::RegisterType::int32);
  EXPECT_EQ(s.x.word_order, drivers::modbus::WordOrder::ba);
  EXPECT_EQ(s.x.scale, 1e-6);
  EXPECT_EQ(s.temperature.offset, -50.0);
  EXPECT_FALSE(s.xdot.present);
  EXPECT_FALSE(s.voltage.present);
  EXPECT_EQ(s.command.address, 200);
  EXPECT_EQ(s.command.type, drivers::modbus::RegisterType::uint16);
}

TEST(ModbusKeys, NoSectionGivesTheSimdaqDefaultMap) {
  const ModbusSettings s = load("modbus:\n");
  EXPECT_TRUE(s.x.present);
  EXPECT_EQ(s.x.address, 0);
  EXPECT_EQ(s.temperature.address, 2);
  EXPECT_EQ(s.x.word_order, drivers::modbus::WordOrder::ab);
  EXPECT_FALSE(s.xdot.present);
}

TEST(ModbusKeys, Float32WithoutWordOrderIsAnError) {
  const std::string e = error_of(R"(modbus:
  signals:
    x: {address: 0, type: float32}
    temperature: {address: 2, type: float32, word_order: ab}
)");
  EXPECT_NE(e.find("test.yaml:3"), std::string::npos) << e;
  EXPECT_NE(e.find("modbus.signals.x.type"), std::string::npos) << e;
  EXPECT_NE(e.find("word_order: ab"), std::string::npos) << e;
}

TEST(ModbusKeys, OverlapNamesBothSignalsAndTheLine) {
  const std::string e = error_of(R"(modbus:
  signals:
    x: {address: 0, type: float32, word_order: ab}
    temperature: {address: 1, type: float32, word_order: ab}
)");
  EXPECT_NE(e.find("test.yaml:4"), std::string::npos) << e;
  EXPECT_NE(e.find("signals.temperature"), std::string::npos) << e;
  EXPECT_NE(e.find("signals.x"), std::string::npos) << e;
}

// The heater's current is an optional signal like ẋ and the read-back: absent by default, read
// where the map gives it, its mistakes named like the others'.
TEST(ModbusKeys, TheHeaterCurrentIsAnOptionalSignal) {
  EXPECT_FALSE(load("modbus:\n").current.present);
  const ModbusSettings s = load(R"(modbus:
  signals:
    x: {address: 0, type: float32, word_order: ab}
    temperature: {address: 2, type: float32, word_order: ab}
    current: {address: 10, type: int16, scale: 0.001}
)");
  EXPECT_TRUE(s.current.present);
  EXPECT_EQ(s.current.address, 10);
  EXPECT_EQ(s.current.type, drivers::modbus::RegisterType::int16);
  EXPECT_EQ(s.current.scale, 0.001);
  std::string e = error_of(R"(modbus:
  signals:
    x: {address: 0, type: float32, word_order: ab}
    temperature: {address: 2, type: float32, word_order: ab}
    current: {address: 3, type: int16}
)");
  EXPECT_NE(e.find("test.yaml:5"), std::string::npos) << e;
  EXPECT_NE(e.find("signals.current"), std::string::npos) << e;
  EXPECT_NE(e.find("signals.temperature"), std::string::npos) << e;
  e = error_of(R"(modbus:
  signals:
    x: {address: 0, type: float32, word_order: ab}
    temperature: {address: 2, type: float32, word_order: ab}
    current: {address: 10, type: int16, scale: 0}
)");
  EXPECT_NE(e.find("modbus.signals.current.scale"), std::string::npos) << e;
}

TEST(ModbusKeys, CommandChecks) {
  // 10 V / 0.0001 = 100000 does not fit int16.
  std::string e = error_of(R"(modbus:
  command: {address: 0, type: int16, scale: 0.0001, min: 0, max: 10}
)");
  EXPECT_NE(e.find("modbus.command.scale"), std::string::npos) << e;
  EXPECT_NE(e.find("does not fit int16"), std::string::npos) << e;
  e = error_of("modbus:\n  command: {address: 0, type: uint16, min: 1, max: 10}\n");
  EXPECT_NE(e.find("modbus.command.min"), std::string::npos) << e;
  EXPECT_NE(e.find("0 V must lie"), std::string::npos) << e;
  e = error_of("modbus:\n  command: {address: 0, type: int32}\n");
  EXPECT_NE(e.find("word_order"), std::string::npos) << e;
  e = error_of(R"(modbus:
  signals:
    x: {address: 0, type: int16}
    temperature: {address: 1, type: int16}
    voltage: {table: holding, address: 0, type: int16}
  command: {address: 0, type: int16, min: 0, max: 10}
)");
  EXPECT_NE(e.find("command"), std::string::npos) << e;
  EXPECT_NE(e.find("signals.voltage"), std::string::npos) << e;
}

// Some devices implement only function 16: a one-register command may use it; function 6 cannot
// write a 32-bit command. The heartbeat register is read too.
TEST(ModbusKeys, CommandFunctionAndWatchdog) {
  const ModbusSettings s = load(R"(modbus:
  command: {address: 5, type: uint16, scale: 0.001, function: 16}
  watchdog: {register: 100, every_cycles: 20}
)");
  EXPECT_EQ(s.command.function, 16);
  EXPECT_EQ(s.watchdog_register, 100);
  EXPECT_EQ(s.watchdog_every, 20);
  EXPECT_EQ(load("modbus: {}\n").command.function, 0);  // auto
  EXPECT_EQ(load("modbus: {}\n").watchdog_register, -1);
  const std::string e = error_of(R"(modbus:
  command: {address: 0, type: float32, word_order: ab, function: 6}
)");
  EXPECT_NE(e.find("command.function"), std::string::npos) << e;
  EXPECT_NE(e.find("use 16"), std::string::npos) << e;
}

TEST(ModbusKeys, OtherMistakes) {
  std::string e = error_of("modbus:\n  transport: rtu\n  unit_id: 0\n");
  EXPECT_NE(e.find("modbus.unit_id"), std::string::npos) << e;
  EXPECT_NE(e.find("1-247"), std::string::npos) << e;
  e = error_of("modbus:\n  signals:\n    xdot: {address: 8, type: int16}\n");
  EXPECT_NE(e.find("modbus.signals.x"), std::string::npos) << e;
  EXPECT_NE(e.find("required"), std::string::npos) << e;
  e = error_of("modbus:\n  signals:\n    x: {address: 0, type: int64}\n");
  EXPECT_NE(e.find("int64"), std::string::npos) << e;
  e = error_of("modbus:\n  response_timeout: 0\n");
  EXPECT_NE(e.find("modbus.response_timeout"), std::string::npos) << e;
  e = error_of(
      "modbus:\n  signals:\n    x: {adress: 0, type: int16}\n    temperature: {address: 1, type: "
      "int16}\n");
  EXPECT_NE(e.find("adress"), std::string::npos) << e;
}

TEST(ModbusKeys, DocumentingModeDeclaresEveryKeyWithoutFailing) {
  Binder root = Binder::documenting();
  Binder m = root.section("modbus", "test");
  ModbusSettings out;
  EXPECT_NO_THROW(declare_modbus_keys(m, out));
  bool has_word_order = false;
  for (const auto& d : root.docs()) has_word_order |= d.path == "modbus.command.word_order";
  EXPECT_TRUE(has_word_order);
}

}  // namespace
}  // namespace scp::config

#include "daemon/config/daemon_config.hpp"
#include "drivers/modbus/timing.hpp"

namespace scp::config {
namespace {

// The shipped examples load through the daemon's loader and fit their loop period.
TEST(ModbusKeys, ExampleConfigsLoadAndFitTheirPeriod) {
  for (const char* name : {"/config/modbus-tcp.yaml", "/config/modbus-rtu.yaml"}) {
    const DaemonConfig cfg = load_config_file(std::string(SCP_SOURCE_DIR) + name);
    EXPECT_EQ(cfg.driver.type, DriverType::modbus) << name;
    EXPECT_TRUE(cfg.driver.modbus.voltage.present) << name;
    EXPECT_NO_THROW(drivers::modbus::check_timing(cfg.driver.modbus, cfg.loop.period_s)) << name;
  }
}

}  // namespace
}  // namespace scp::config

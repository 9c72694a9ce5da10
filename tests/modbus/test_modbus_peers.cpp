// Peers nobody here wrote: the driver against a python3-pymodbus server, mbpoll against
// scp-simdaq, and the driver against scp-simdaq over Modbus RTU on a socat pty pair.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <memory>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include "drivers/modbus/modbus_driver.hpp"
#include "io_helpers.hpp"
#include "tests/support/peer_required.hpp"

namespace scp::drivers::modbus {
namespace {

using test::ChildProcess;

TEST(ModbusPeers, DriverReadsAPymodbusServer) {
  const std::string python = "/usr/bin/python3";
  if (!test::executable(python) ||
      std::system("/usr/bin/python3 -c 'import pymodbus.server' >/dev/null 2>&1") != 0) {
    SCP_PEER_MISSING(
        "Debian's python3-pymodbus (with python3-serial, python3-serial-asyncio) is not "
        "usable: apt install python3-pymodbus python3-serial python3-serial-asyncio");
  }
  const int port = test::free_port();
  ChildProcess server(
      {python, std::string(SCP_MODBUS_TEST_DIR) + "/pymodbus_server.py", std::to_string(port)});
  ASSERT_TRUE(server.wait_for("pymodbus server ready", 15.0)) << server.output();

  // The map documented in pymodbus_server.py, with a different type in every signal.
  ModbusSettings s;
  s.port = port;
  s.response_timeout_s = 0.2;
  s.x = {true, Table::input, 0, RegisterType::int32, WordOrder::ba, 1e-6, 0.0};
  s.temperature = {true, Table::input, 2, RegisterType::float32, WordOrder::ab, 1.0, 0.0};
  s.xdot = {true, Table::input, 4, RegisterType::int16, WordOrder::none, 1e-5, 0.0};
  s.voltage = {true, Table::holding, 0, RegisterType::uint16, WordOrder::none, 0.001, 0.0};
  s.command.address = 10;
  ModbusDriver driver(s, 1.0);
  // The server prints "ready" just before it binds: open() then finds nobody and the reconnect
  // thread connects a little later, as for a DAQ that is slow at start.
  driver.open();
  Sample out;
  IoStatus got = IoStatus::error;
  for (int i = 0; i < 100 && got != IoStatus::ok; ++i) {
    got = driver.read({0.0, 1.0}, out).status;
    if (got != IoStatus::ok) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_EQ(got, IoStatus::ok) << driver.background_error();
  EXPECT_DOUBLE_EQ(out.x, -0.00125);
  EXPECT_EQ(out.temperature, 31.5);
  EXPECT_DOUBLE_EQ(out.xdot, -7e-5);
  EXPECT_DOUBLE_EQ(out.voltage, 1.5);
  ASSERT_EQ(driver.write_voltage(2.25).status, IoStatus::ok);
  std::array<std::uint16_t, 2> regs{};
  ASSERT_TRUE(test::read_holding(port, 10, 2, regs.data()));
  EXPECT_EQ(regs[0], 0x4010);  // 2.25f = 0x40100000
  EXPECT_EQ(regs[1], 0x0000);
  driver.close();
  ASSERT_TRUE(test::read_holding(port, 10, 2, regs.data()));
  EXPECT_EQ(regs[0], 0);
}

// mbpoll prints "[ref]: \tvalue" per register (refs are 1-based).
double mbpoll_value(const std::string& out, int ref) {
  const std::regex re("\\[" + std::to_string(ref) + "\\]:\\s+(\\S+)");
  std::smatch m;
  if (!std::regex_search(out, m, re)) return std::nan("");
  return std::stod(m[1]);
}

TEST(ModbusPeers, MbpollReadsSimdaqRegistersAsDocumented) {
  const std::string mbpoll = "/usr/bin/mbpoll";
  if (!test::executable(mbpoll)) SCP_PEER_MISSING("mbpoll is not installed (apt install mbpoll)");
  const std::string config = test::temp_file(test::kSimdaqConfig);
  int port = 0;
  auto daq = test::start_simdaq(config, port);
  const std::string p = std::to_string(port);
  // Input registers 1..8 (protocol 0..7) as big-endian-word floats: x, T, ẋ, V.
  ChildProcess read1({mbpoll, "-m", "tcp", "-p", p, "-a", "1", "-t", "3:float", "-B", "-r", "1",
                      "-c", "4", "-1", "127.0.0.1"});
  ASSERT_EQ(read1.wait_exit(10.0), 0) << read1.output();
  EXPECT_NEAR(mbpoll_value(read1.output(), 3), 25.0, 1e-4) << read1.output();
  EXPECT_EQ(mbpoll_value(read1.output(), 7), 0.0) << read1.output();
  // Command register: holding 1..2 (protocol 0..1), float32 ab.
  ChildProcess write({mbpoll, "-m", "tcp", "-p", p, "-a", "1", "-t", "4:float", "-B", "-r", "1",
                      "127.0.0.1", "--", "1.5"});
  ASSERT_EQ(write.wait_exit(10.0), 0) << write.output();
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  ChildProcess read2({mbpoll, "-m", "tcp", "-p", p, "-a", "1", "-t", "3:float", "-B", "-r", "1",
                      "-c", "4", "-1", "127.0.0.1"});
  ASSERT_EQ(read2.wait_exit(10.0), 0) << read2.output();
  EXPECT_EQ(mbpoll_value(read2.output(), 7), 1.5) << read2.output();   // V read-back
  EXPECT_GT(mbpoll_value(read2.output(), 3), 25.0) << read2.output();  // heating
  std::remove(config.c_str());
}

// scp-simdaq serving RTU at 115200 Bd on one end of a socat pty pair; `device` is the other end.
class RtuPtyPair : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string socat = "/usr/bin/socat";
    if (!test::executable(socat)) SCP_PEER_MISSING("socat is not installed (apt install socat)");
    link_ = std::make_unique<ChildProcess>(
        std::vector<std::string>{socat, "-d", "-d", "pty,raw,echo=0", "pty,raw,echo=0"});
    ASSERT_TRUE(link_->wait_for("starting data transfer loop", 10.0)) << link_->output();
    const std::regex re("PTY is (/dev/pts/[0-9]+)");
    std::vector<std::string> ptys;
    const std::string out = link_->output();
    for (auto it = std::sregex_iterator(out.begin(), out.end(), re); it != std::sregex_iterator();
         ++it) {
      ptys.push_back((*it)[1]);
    }
    ASSERT_EQ(ptys.size(), 2u) << out;
    std::string yaml = test::kSimdaqConfig;
    yaml.replace(yaml.find("transport: tcp"), 14, "transport: rtu\n    rtu: {baud: 115200}");
    config_ = test::temp_file(yaml);
    daq_ = std::make_unique<ChildProcess>(
        std::vector<std::string>{SCP_SIMDAQ_PATH, "--config", config_, "--device", ptys[0]});
    ASSERT_TRUE(daq_->wait_for("scp-simdaq: serving " + ptys[0], 10.0)) << daq_->output();
    device_ = ptys[1];
  }
  void TearDown() override {
    if (!config_.empty()) std::remove(config_.c_str());
  }
  ModbusSettings settings() const {
    ModbusSettings s;
    s.transport = Transport::rtu;
    s.device = device_;
    s.baud = 115200;
    s.response_timeout_s = 0.1;
    s.xdot.present = true;
    s.voltage.present = true;
    return s;
  }
  std::unique_ptr<ChildProcess> link_;
  std::unique_ptr<ChildProcess> daq_;
  std::string config_;
  std::string device_;
};

TEST_F(RtuPtyPair, RtuOverASocatPtyPair) {
  ModbusDriver driver(settings(), 0.5);
  driver.open();
  Sample sample;
  ASSERT_EQ(driver.read({0.0, 0.5}, sample).status, IoStatus::ok);
  EXPECT_NEAR(sample.temperature, 25.0, 1e-4);
  ASSERT_EQ(driver.write_voltage(1.0).status, IoStatus::ok);
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  ASSERT_EQ(driver.read({0.5, 0.5}, sample).status, IoStatus::ok);
  EXPECT_EQ(sample.voltage, 1.0);
  EXPECT_GT(sample.temperature, 25.0);
  driver.close();
}

// safe_state() outside a cycle, after the cycle's I/O budget ran out (the loop's shutdown, a fault
// raised late in a cycle): the silence before its request and the reply still get their time, so
// 0 V goes out (with an expired budget the request was never sent: EBUSY at once).
TEST_F(RtuPtyPair, SafeStateAfterTheCycleBudgetRanOutStillDeliversZeroVolts) {
  ModbusSettings s = settings();
  s.response_timeout_s = 0.02;
  const double period = 0.05;
  ModbusDriver driver(s, period);
  driver.open();
  Sample sample;
  ASSERT_EQ(driver.read({0.0, period}, sample).status, IoStatus::ok);
  ASSERT_EQ(driver.write_voltage(1.0).status, IoStatus::ok);
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  ASSERT_EQ(driver.read({period, period}, sample).status, IoStatus::ok);  // a fresh budget
  EXPECT_EQ(sample.voltage, 1.0);
  std::this_thread::sleep_for(std::chrono::duration<double>(period + 0.02));
  const std::uint64_t errors = driver.stats().write_errors;
  driver.safe_state();
  EXPECT_EQ(driver.stats().write_errors, errors);
  EXPECT_TRUE(driver.stats().output_confirmed);
  EXPECT_EQ(driver.stats().output_v, 0.0);
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  ASSERT_EQ(driver.read({3 * period, period}, sample).status, IoStatus::ok);
  EXPECT_EQ(sample.voltage, 0.0) << "0 V never reached the DAQ";
  driver.close();
}

}  // namespace
}  // namespace scp::drivers::modbus

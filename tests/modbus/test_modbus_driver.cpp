// ModbusDriver against scp-simdaq over Modbus TCP on 127.0.0.1: values match an independent
// integration of the plant, commands reach it, and every fault walks the documented status path.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <chrono>
#include <cmath>
#include <ctime>
#include <limits>
#include <string>
#include <thread>

#include "daemon/config/binder.hpp"
#include "daemon/config/keys_modbus.hpp"
#include "drivers/modbus/modbus_driver.hpp"
#include "io_helpers.hpp"

namespace scp::drivers::modbus {
namespace {

using Clock = std::chrono::steady_clock;
using test::ChildProcess;

ModbusSettings settings_for(int port, const char* yaml = test::kSimdaqConfig) {
  config::Binder root = config::Binder::reading(YAML::Load(yaml), "test");
  config::Binder driver = root.section("driver", "");
  config::Binder m = driver.section("modbus", "");
  ModbusSettings s;
  config::declare_modbus_keys(m, s);
  s.port = port;
  s.response_timeout_s = 0.02;
  s.max_consecutive_failures = 3;
  s.reconnect_initial_s = 0.05;
  s.reconnect_max_s = 0.2;
  return s;
}

constexpr double kPeriod = 0.05;  // the loop period the tests pretend to run at

// Table I plant, integrated here with RK4 at 0.1 ms from rest with V held: the reference the
// served values are compared with (independent of drivers/sim).
struct Reference {
  double x, xdot, tbar;
};
Reference integrate_table1(double volts, double seconds) {
  const double m = 0.1, R = 1.0, Cth = 0.9090, lam = 0.0540, b = 124.7, k = 181.3, a1 = 0.08,
               a2 = 0.01;
  auto f = [&](const std::array<double, 3>& s) {
    const double x = s[0], v = s[1], T = s[2];
    return std::array<double, 3>{v, (-b * v - a1 * T * v - k * x - a2 * T) / m,
                                 (-lam * T + volts * volts / R) / Cth};
  };
  std::array<double, 3> s{0, 0, 0};
  const double h = 1e-4;
  const int n = static_cast<int>(std::lround(seconds / h));
  for (int i = 0; i < n; ++i) {
    const auto k1 = f(s);
    std::array<double, 3> t{};
    for (int j = 0; j < 3; ++j) t[j] = s[j] + 0.5 * h * k1[j];
    const auto k2 = f(t);
    for (int j = 0; j < 3; ++j) t[j] = s[j] + 0.5 * h * k2[j];
    const auto k3 = f(t);
    for (int j = 0; j < 3; ++j) t[j] = s[j] + h * k3[j];
    const auto k4 = f(t);
    for (int j = 0; j < 3; ++j) s[j] += h / 6 * (k1[j] + 2 * k2[j] + 2 * k3[j] + k4[j]);
  }
  return {s[0], s[1], s[2]};
}

class ModbusDriverTest : public ::testing::Test {
 protected:
  void SetUp() override { config_ = test::temp_file(test::kSimdaqConfig); }
  void TearDown() override { std::remove(config_.c_str()); }
  std::string config_;
};

TEST_F(ModbusDriverTest, ValuesMatchThePlantAndTheCommandReachesIt) {
  int port = 0;
  auto daq = test::start_simdaq(config_, port);
  ModbusDriver driver(settings_for(port), kPeriod);
  driver.open();
  ASSERT_EQ(driver.plan().blocks.size(), 1u);  // x, T, ẋ, V in input 0-7: one request
  Sample s;
  ASSERT_EQ(driver.read({0.0, kPeriod}, s).status, IoStatus::ok);
  EXPECT_NEAR(s.temperature, 25.0, 1e-5);  // at rest at the simulator's ambient
  EXPECT_EQ(s.x, 0.0);
  EXPECT_EQ(s.voltage, 0.0);

  ASSERT_EQ(driver.write_voltage(2.0).status, IoStatus::ok);
  const auto t0 = Clock::now();
  std::this_thread::sleep_until(t0 + std::chrono::milliseconds(1500));
  ASSERT_EQ(driver.read({1.5, kPeriod}, s).status, IoStatus::ok);
  const double elapsed = std::chrono::duration<double>(Clock::now() - t0).count();
  EXPECT_EQ(s.voltage, 2.0);  // read back exactly: 2.0 is a float32
  const Reference r = integrate_table1(2.0, elapsed);
  // The served state is up to one plant period (1 ms) plus a transaction old: dT/dt ≈ 4.4 °C/s.
  EXPECT_NEAR(s.temperature - 25.0, r.tbar, 0.03) << "elapsed " << elapsed;
  EXPECT_NEAR(s.x, r.x, 0.03 * std::fabs(r.x)) << "elapsed " << elapsed;
  EXPECT_NEAR(s.xdot, r.xdot, 0.05 * std::fabs(r.xdot) + 1e-7) << "elapsed " << elapsed;
  EXPECT_LT(r.x, 0.0);  // heating contracts the actuator (−α2 T̄)
  const DriverStats st = driver.stats();
  EXPECT_EQ(st.reads, 2u);
  EXPECT_EQ(st.read_errors, 0u);
  driver.close();
  // close() leaves the DAQ at 0 V.
  std::array<std::uint16_t, 2> regs{9, 9};
  ASSERT_TRUE(test::read_holding(port, 0, 2, regs.data()));
  EXPECT_EQ(regs[0], 0);
  EXPECT_EQ(regs[1], 0);
}

// scp-simdaq's map with the heater's current, which its simulated DAQ measures.
constexpr const char* kCurrentConfig = R"(driver:
  type: modbus
  sim: {measure_current: true}
  modbus:
    transport: tcp
    signals:
      x: {table: input, address: 0, type: float32, word_order: ab}
      temperature: {table: input, address: 2, type: float32, word_order: ab}
      current: {table: input, address: 8, type: int16, scale: 0.0001}
    command: {address: 0, type: float32, word_order: ab, min: 0, max: 10}
)";

// The heater's current decoded like the other signals: scp-simdaq serves V/R of its plant
// (Table I: R = 1 Ω) through a 0.1 mA int16 register; absent from the map, it is not measured.
TEST_F(ModbusDriverTest, TheHeaterCurrentIsDecodedWhereTheMapHasIt) {
  const std::string config = test::temp_file(kCurrentConfig);
  int port = 0;
  auto daq = test::start_simdaq(config, port);
  ModbusDriver driver(settings_for(port, kCurrentConfig), kPeriod);
  driver.open();
  ASSERT_EQ(driver.write_voltage(2.0).status, IoStatus::ok);
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  Sample s;
  ASSERT_EQ(driver.read({0.2, kPeriod}, s).status, IoStatus::ok);
  EXPECT_NEAR(s.current, 2.0, 1e-4);
  EXPECT_TRUE(std::isnan(s.xdot));
  driver.close();
  daq.reset();
  std::remove(config.c_str());

  port = 0;
  auto plain = test::start_simdaq(config_, port);
  ModbusDriver without(settings_for(port), kPeriod);
  without.open();
  ASSERT_EQ(without.read({0.0, kPeriod}, s).status, IoStatus::ok);
  EXPECT_TRUE(std::isnan(s.current));
  without.close();
}

std::int64_t monotonic_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// Real time: a sample is stamped inside its read transaction and a command inside its write, on
// the loop's clock; batch and lock-step runs (deadline_ns = 0) and timing.stamp: false keep the
// deadline and −∞. Against scp-simdaq's wall-clock plant behind its emulated line, so that the
// transactions take milliseconds (8 + 3.5 + 21 characters of 86.8 µs: 2.8 ms for the read).
TEST_F(ModbusDriverTest, SamplesAndCommandsAreStampedWithTheirTransactionsInRealTimeOnly) {
  int port = 0;
  auto daq = test::start_simdaq(config_, port, {"--wallclock", "--wire"});
  ModbusDriver driver(settings_for(port), kPeriod);
  driver.open();
  Sample s;
  // The loop's deadline t = 2 s was 5 ms ago.
  const std::int64_t deadline = monotonic_ns() - 5'000'000;
  const auto loop_t = [&](std::int64_t ns) {
    return 2.0 + static_cast<double>(ns - deadline) * 1e-9;
  };
  std::int64_t begin = monotonic_ns();
  ASSERT_EQ(driver.read({2.0, kPeriod, deadline}, s).status, IoStatus::ok);
  std::int64_t end = monotonic_ns();
  EXPECT_GT(end - begin, 2'500'000) << "the emulated line takes 2.8 ms for this read";
  // Over TCP the driver knows no wire: the midpoint.
  EXPECT_GE(s.t, loop_t(begin));
  EXPECT_LE(s.t, loop_t(end));
  EXPECT_NEAR(s.t, 0.5 * (loop_t(begin) + loop_t(end)), 0.5e-3);
  EXPECT_EQ(s.voltage_since, -std::numeric_limits<double>::infinity());  // nothing written yet
  const double first_t = s.t;

  begin = monotonic_ns();
  ASSERT_EQ(driver.write_voltage(1.0).status, IoStatus::ok);
  end = monotonic_ns();
  ASSERT_EQ(driver.read({2.0 + kPeriod, kPeriod, deadline + 50'000'000}, s).status, IoStatus::ok);
  EXPECT_GE(s.voltage_since, loop_t(begin));
  EXPECT_LE(s.voltage_since, loop_t(end));
  EXPECT_GT(s.voltage_since, first_t);
  EXPECT_LT(s.voltage_since, s.t);
  EXPECT_EQ(s.voltage, 1.0);

  // Batch / lock-step: no wall clock, the deadline and −∞, exactly.
  ASSERT_EQ(driver.read({3.0, kPeriod}, s).status, IoStatus::ok);
  EXPECT_EQ(s.t, 3.0);
  driver.close();

  ModbusSettings unstamped = settings_for(port);
  unstamped.timing.stamp = false;
  ModbusDriver deadlines(unstamped, kPeriod);
  deadlines.open();
  ASSERT_EQ(deadlines.write_voltage(1.0).status, IoStatus::ok);
  ASSERT_EQ(deadlines.read({4.0, kPeriod, monotonic_ns() - 5'000'000}, s).status, IoStatus::ok);
  EXPECT_EQ(s.t, 4.0);
  EXPECT_EQ(s.voltage_since, -std::numeric_limits<double>::infinity());
  deadlines.close();
}

TEST_F(ModbusDriverTest, SafeStateWritesZeroToTheCommandRegister) {
  int port = 0;
  auto daq = test::start_simdaq(config_, port);
  ModbusDriver driver(settings_for(port), kPeriod);
  driver.open();
  ASSERT_EQ(driver.write_voltage(2.0).status, IoStatus::ok);
  std::array<std::uint16_t, 2> regs{};
  ASSERT_TRUE(test::read_holding(port, 0, 2, regs.data()));
  EXPECT_EQ(regs[0], 0x4000);  // 2.0f = 0x40000000, high word first (ab)
  EXPECT_EQ(regs[1], 0x0000);
  driver.safe_state();
  driver.safe_state();  // callable any number of times
  ASSERT_TRUE(test::read_holding(port, 0, 2, regs.data()));
  EXPECT_EQ(regs[0], 0);
  EXPECT_EQ(regs[1], 0);
  EXPECT_EQ(driver.last_command(), 0.0);
  // Refused commands also leave 0 V.
  ASSERT_EQ(driver.write_voltage(1.0).status, IoStatus::ok);
  EXPECT_EQ(driver.write_voltage(std::nan("")).status, IoStatus::error);
  EXPECT_EQ(driver.write_voltage(11.0).status, IoStatus::error);  // command.max is 10
  ASSERT_TRUE(test::read_holding(port, 0, 2, regs.data()));
  EXPECT_EQ(regs[0], 0);
}

// safe_state() outside a cycle (the loop's shutdown, a fault raised late in a cycle) comes when
// the cycle's I/O budget has run out: its 0 V still gets a whole transaction, reply included.
TEST_F(ModbusDriverTest, SafeStateAfterTheCycleBudgetRanOutStillDeliversZeroVolts) {
  int port = 0;
  auto daq = test::start_simdaq(config_, port);
  ModbusDriver driver(settings_for(port), kPeriod);
  driver.open();
  Sample s;
  ASSERT_EQ(driver.read({0.0, kPeriod}, s).status, IoStatus::ok);  // the budget: one period
  ASSERT_EQ(driver.write_voltage(2.0).status, IoStatus::ok);
  std::this_thread::sleep_for(std::chrono::duration<double>(kPeriod + 0.02));
  const std::uint64_t errors = driver.stats().write_errors;
  driver.safe_state();
  EXPECT_EQ(driver.stats().write_errors, errors);
  EXPECT_TRUE(driver.stats().output_confirmed) << "the reply to 0 V was not awaited";
  EXPECT_EQ(driver.stats().output_v, 0.0);
  std::array<std::uint16_t, 2> regs{9, 9};
  ASSERT_TRUE(test::read_holding(port, 0, 2, regs.data()));
  EXPECT_EQ(regs[0], 0);
  EXPECT_EQ(regs[1], 0);
  driver.close();
}

// A DAQ absent at start is a link lost before it was ever up (issue 9): open() returns, reads
// report why, the output is not confirmed, and the reconnect thread keeps trying. An offline
// run has nobody to wait for and still refuses at once. Impossible timing is always refused.
TEST_F(ModbusDriverTest, UnreachableDeviceIsWaitedForOnlineRefusedOfflineAndTimingRefused) {
  ModbusSettings absent = settings_for(test::free_port());
  ModbusDriver nobody(absent, kPeriod);
  nobody.open();
  EXPECT_FALSE(nobody.stats().link_up);
  EXPECT_FALSE(nobody.stats().output_confirmed);
  Sample s;
  IoResult r;
  for (int i = 0; i <= absent.max_consecutive_failures; ++i) r = nobody.read({0.0, kPeriod}, s);
  EXPECT_EQ(r.status, IoStatus::error);
  EXPECT_NE(std::string(r.reason).find("no answer from tcp 127.0.0.1:"), std::string::npos)
      << r.reason;
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  EXPECT_NE(nobody.background_error().find("tcp.host/port"), std::string::npos)
      << nobody.background_error();
  nobody.close();
  absent.enforce_period_budget = false;  // what scp-estimatord --offline sets
  ModbusDriver offline(absent, kPeriod);
  try {
    offline.open();
    FAIL() << "connected to nothing";
  } catch (const DriverError& e) {
    EXPECT_NE(std::string(e.what()).find("tcp.host/port"), std::string::npos) << e.what();
  }
  ModbusDriver too_fast(settings_for(1502), 0.001);  // 20 ms timeout × 2 in a 1 ms period
  try {
    too_fast.open();
    FAIL() << "timing accepted";
  } catch (const DriverError& e) {
    EXPECT_NE(std::string(e.what()).find("exceeds the 1 ms loop period"), std::string::npos)
        << e.what();
  }
}

// Reads like the loop would (every 5 ms), returning each status; fails the test if one call
// blocks longer than the response timeout plus scheduling slack.
IoStatus timed_read(ModbusDriver& d, double timeout_s, const char** reason = nullptr) {
  Sample s;
  const auto t0 = Clock::now();
  const IoResult r = d.read({0.0, kPeriod}, s);
  const double took = std::chrono::duration<double>(Clock::now() - t0).count();
  EXPECT_LT(took, timeout_s + 0.015) << "read() blocked " << took << " s: " << r.reason;
  if (reason != nullptr) *reason = r.reason;
  std::this_thread::sleep_for(std::chrono::milliseconds(5));
  return r.status;
}

TEST_F(ModbusDriverTest, ServerKilledAndRestartedIsReconnectedWithoutBlockingTheLoop) {
  int port = 0;
  auto daq = test::start_simdaq(config_, port);
  const ModbusSettings settings = settings_for(port);
  ModbusDriver driver(settings, kPeriod);
  driver.open();
  ASSERT_EQ(timed_read(driver, settings.response_timeout_s), IoStatus::ok);
  ASSERT_EQ(driver.write_voltage(1.0).status, IoStatus::ok);

  daq->stop(SIGKILL);
  // max_consecutive_failures = 3: three reads tolerated as no_data, then the loop is told.
  const char* reason = "";
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(timed_read(driver, settings.response_timeout_s, &reason), IoStatus::no_data) << i;
  }
  EXPECT_EQ(timed_read(driver, settings.response_timeout_s, &reason), IoStatus::error);
  EXPECT_NE(std::string(reason).find("modbus:"), std::string::npos);
  EXPECT_FALSE(driver.stats().link_up);
  EXPECT_EQ(driver.stats().reconnects, 0u);
  // The link stays down while nobody listens, and every call still returns promptly.
  for (int i = 0; i < 40; ++i) {
    EXPECT_EQ(timed_read(driver, settings.response_timeout_s), IoStatus::error);
  }

  int same_port = port;
  daq = test::start_simdaq(config_, same_port);
  ASSERT_EQ(same_port, port);
  // After reconnection the first write sends 0 V, whatever is asked, until a fresh reading.
  IoStatus w = IoStatus::error;
  for (int i = 0; i < 400 && w != IoStatus::ok; ++i) {
    Clock::time_point t0 = Clock::now();
    w = driver.write_voltage(1.0).status;
    EXPECT_LT(std::chrono::duration<double>(Clock::now() - t0).count(),
              settings.response_timeout_s + 0.015);
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_EQ(w, IoStatus::ok) << "link not restored";
  EXPECT_EQ(driver.last_command(), 0.0);
  EXPECT_TRUE(driver.stats().link_up);
  EXPECT_EQ(driver.stats().reconnects, 1u);
  EXPECT_EQ(timed_read(driver, settings.response_timeout_s), IoStatus::ok);
  ASSERT_EQ(driver.write_voltage(1.0).status, IoStatus::ok);
  EXPECT_EQ(driver.last_command(), 1.0);
  std::array<std::uint16_t, 2> regs{};
  ASSERT_TRUE(test::read_holding(port, 0, 2, regs.data()));
  EXPECT_EQ(regs[0], 0x3F80);  // 1.0f
}

TEST_F(ModbusDriverTest, SlaveThatStopsAnsweringTimesOutThenFaults) {
  int port = 0;
  auto daq = test::start_simdaq(config_, port, {"--fault-after", "0.4"});
  const ModbusSettings settings = settings_for(port);
  ModbusDriver driver(settings, kPeriod);
  driver.open();
  ASSERT_EQ(timed_read(driver, settings.response_timeout_s), IoStatus::ok);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  const char* reason = "";
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(timed_read(driver, settings.response_timeout_s, &reason), IoStatus::no_data) << i;
    EXPECT_NE(std::string(reason).find("no reply within driver.modbus.response_timeout"),
              std::string::npos)
        << reason;
  }
  EXPECT_EQ(timed_read(driver, settings.response_timeout_s, &reason), IoStatus::error);
  EXPECT_NE(std::string(reason).find("read input registers 0-7"), std::string::npos) << reason;
  // The reconnect thread connects but its probe gets no answer: no link is handed over.
  for (int i = 0; i < 30; ++i) {
    EXPECT_EQ(timed_read(driver, settings.response_timeout_s), IoStatus::error);
  }
  EXPECT_EQ(driver.stats().reconnects, 0u);
  EXPECT_FALSE(driver.stats().link_up);
  EXPECT_GE(driver.stats().read_errors, 34u);
}

TEST_F(ModbusDriverTest, ExceptionRepliesNameFunctionAndAddress) {
  int port = 0;
  auto daq =
      test::start_simdaq(config_, port, {"--exception-after", "0.3", "--exception-code", "2"});
  const ModbusSettings settings = settings_for(port);
  ModbusDriver driver(settings, kPeriod);
  driver.open();
  ASSERT_EQ(timed_read(driver, settings.response_timeout_s), IoStatus::ok);
  std::this_thread::sleep_for(std::chrono::milliseconds(400));
  const char* reason = "";
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(timed_read(driver, settings.response_timeout_s, &reason), IoStatus::no_data) << i;
  }
  EXPECT_EQ(timed_read(driver, settings.response_timeout_s, &reason), IoStatus::error);
  const std::string r = reason;
  EXPECT_NE(r.find("read input registers 0-7 (function 4)"), std::string::npos) << r;
  EXPECT_NE(r.find("exception 2 (illegal data address"), std::string::npos) << r;
  const IoResult w = driver.write_voltage(1.0);
  EXPECT_EQ(w.status, IoStatus::no_data);
  EXPECT_NE(std::string(w.reason).find("write holding registers 0-1 (function 16): exception 2"),
            std::string::npos)
      << w.reason;
  EXPECT_TRUE(driver.stats().link_up);  // an exception is an answer: the link is fine
  EXPECT_EQ(driver.stats().reconnects, 0u);
}

}  // namespace
}  // namespace scp::drivers::modbus

#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <vector>

#include "drivers/driver.hpp"
#include "drivers/modbus/read_plan.hpp"
#include "drivers/modbus/timing.hpp"

namespace scp::drivers::modbus {
namespace {

RegisterSignal at(Table table, int address, RegisterType type = RegisterType::float32) {
  return {true, table, address, type, WordOrder::ab, 1.0, 0.0};
}

ModbusSettings two_signals(int x_address, int t_address) {
  ModbusSettings s;
  s.x = at(Table::input, x_address);
  s.temperature = at(Table::input, t_address);
  s.xdot.present = false;
  s.voltage.present = false;
  return s;
}

TEST(ReadPlan, AdjacentSignalsAreOneRead) {
  const ReadPlan plan = plan_reads(two_signals(0, 2), 8);  // x 0-1, T 2-3
  ASSERT_EQ(plan.blocks.size(), 1u);
  EXPECT_EQ(plan.blocks[0], (ReadBlock{Table::input, 0, 4}));
  EXPECT_EQ(plan.slots[0].block, 0);
  EXPECT_EQ(plan.slots[0].offset, 0);
  EXPECT_EQ(plan.slots[2].offset, 2);
  EXPECT_EQ(plan.slots[1].block, -1);  // xdot absent
}

TEST(ReadPlan, GapUpToMaxIsReadThroughLargerGapSplits) {
  // x 0-1, T 10-11: 8 registers between them.
  ReadPlan plan = plan_reads(two_signals(0, 10), 8);
  ASSERT_EQ(plan.blocks.size(), 1u);
  EXPECT_EQ(plan.blocks[0], (ReadBlock{Table::input, 0, 12}));
  EXPECT_EQ(plan.slots[2].offset, 10);
  plan = plan_reads(two_signals(0, 11), 8);  // 9 between: two reads
  ASSERT_EQ(plan.blocks.size(), 2u);
  EXPECT_EQ(plan.blocks[1], (ReadBlock{Table::input, 11, 2}));
  EXPECT_EQ(plan.slots[2].block, 1);
  EXPECT_EQ(plan.slots[2].offset, 0);
}

TEST(ReadPlan, OrderAndTablesAndRequestLimit) {
  ModbusSettings s = two_signals(20, 0);  // T before x in address order
  s.xdot = at(Table::input, 2, RegisterType::int16);
  s.voltage = at(Table::holding, 0, RegisterType::uint16);
  s.command.address = 10;
  ReadPlan plan = plan_reads(s, 100);
  ASSERT_EQ(plan.blocks.size(), 2u);
  EXPECT_EQ(plan.blocks[0], (ReadBlock{Table::input, 0, 22}));
  EXPECT_EQ(plan.blocks[1], (ReadBlock{Table::holding, 0, 1}));
  EXPECT_EQ(plan.slots[0].offset, 20);
  EXPECT_EQ(plan.slots[1].offset, 2);
  EXPECT_EQ(plan.slots[3].block, 1);
  // One request reads at most 125 registers.
  plan = plan_reads(two_signals(0, 124), 200);  // would need 126
  EXPECT_EQ(plan.blocks.size(), 2u);
  plan = plan_reads(two_signals(0, 123), 200);  // exactly 125
  EXPECT_EQ(plan.blocks.size(), 1u);
}

TEST(ReadPlan, OverlapNamesBothSignals) {
  ModbusSettings s = two_signals(0, 1);  // x 0-1 and T 1-2 share register 1
  try {
    plan_reads(s, 8);
    FAIL() << "overlap not detected";
  } catch (const DriverError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("signals.x"), std::string::npos) << what;
    EXPECT_NE(what.find("signals.temperature"), std::string::npos) << what;
  }
  s = two_signals(0, 2);
  s.voltage = at(Table::holding, 4);
  s.command.address = 5;  // command 5-6 overlaps read-back 4-5
  EXPECT_THROW(plan_reads(s, 8), DriverError);
  s.voltage.table = Table::input;  // same numbers in the other table: no clash
  s.voltage.address = 6;
  EXPECT_NO_THROW(plan_reads(s, 8));
}

TEST(CheckTiming, BudgetIsTimeoutTimesTransactions) {
  ModbusSettings s = two_signals(0, 2);  // one read + one write
  s.response_timeout_s = 0.005;
  try {
    check_timing(s, 0.001);
    FAIL() << "5 ms x 2 accepted in a 1 ms period";
  } catch (const DriverError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("5 ms x 2 transactions"), std::string::npos) << what;
    EXPECT_NE(what.find("1 ms loop period"), std::string::npos) << what;
    EXPECT_NE(what.find("loop.period"), std::string::npos) << what;
    EXPECT_NE(what.find("at most 0.5 ms"), std::string::npos) << what;
  }
  EXPECT_NO_THROW(check_timing(s, 0.010));
  s.response_timeout_s = 0.0005;
  EXPECT_NO_THROW(check_timing(s, 0.001));
  s.temperature.address = 40;  // now two reads + a write = 1.5 ms
  EXPECT_EQ(transactions_per_cycle(s), 3);
  EXPECT_THROW(check_timing(s, 0.001), DriverError);
}

// One read of x and T (4 registers) and a float32 command (function 16, 2 registers) on an RTU
// line: the frames' characters from the Modbus serial line specification, counted here again.
ModbusSettings rtu_line(int baud, double timeout_s) {
  ModbusSettings s = two_signals(0, 2);
  s.transport = Transport::rtu;
  s.baud = baud;
  s.response_timeout_s = timeout_s;
  return s;
}

TEST(CheckTiming, LineWarningsCountFramesAndSilences) {
  const double char_s = 10.0 / 115200.0;              // 8N1
  const double read_s = (8 + (5 + 2 * 4)) * char_s;   // request + 4-register reply
  const double write_s = ((9 + 2 * 2) + 8) * char_s;  // function 16 + its echo
  const LineCycle line = line_cycle(rtu_line(115200, 0.008));
  EXPECT_EQ(line.transactions, 2);
  EXPECT_NEAR(line.wire_s, read_s + write_s, 1e-9);
  EXPECT_NEAR(line.longest_exchange_s, std::max(read_s, write_s), 1e-9);
  EXPECT_NEAR(line.longest_first_byte_s, (9 + 2 * 2 + 1) * char_s, 1e-9);  // function 16's
  EXPECT_NEAR(line.silences_s, 2 * 1.75e-3, 1e-9);                         // fixed above 19200 Bd

  EXPECT_TRUE(line_timing_warnings(rtu_line(115200, 0.008), 0.020).empty());  // 2 x 8 + 3.5
  ModbusSettings tcp = rtu_line(115200, 0.010);
  tcp.transport = Transport::tcp;
  EXPECT_TRUE(line_timing_warnings(tcp, 0.020).empty());

  auto only = [](const std::vector<std::string>& w, const char* what) {
    EXPECT_EQ(w.size(), 1u);
    return !w.empty() && w[0].find(what) != std::string::npos;
  };
  const auto silences = line_timing_warnings(rtu_line(115200, 0.010), 0.020);  // 23.5 ms
  EXPECT_TRUE(only(silences, "t3.5 silences (3.5 ms)")) << silences[0];
  EXPECT_NE(silences[0].find("lower the timeout to 8.25 ms"), std::string::npos) << silences[0];
  // The timeout bounds the wait for the reply's first character: the request's 13 and that one.
  const auto short_timeout = line_timing_warnings(rtu_line(115200, 0.001), 0.020);
  EXPECT_TRUE(only(short_timeout, "shorter than the 1.22 ms")) << short_timeout[0];
  EXPECT_TRUE(line_timing_warnings(rtu_line(115200, 0.0013), 0.020).empty());
  // 9600 Bd: the frames alone (43.8 ms) and the silences (7.3 ms) overrun a 20 ms period.
  const auto slow = line_timing_warnings(rtu_line(9600, 0.009), 0.020);
  ASSERT_EQ(slow.size(), 2u);
  EXPECT_NE(slow[0].find("shorter than"), std::string::npos) << slow[0];
  EXPECT_NE(slow[1].find("more than the 20 ms loop period"), std::string::npos) << slow[1];
}

}  // namespace
}  // namespace scp::drivers::modbus

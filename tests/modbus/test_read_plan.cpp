#include <gtest/gtest.h>

#include <string>

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

}  // namespace
}  // namespace scp::drivers::modbus

#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "drivers/replay/replay_driver.hpp"
#include "tests/replay/trace_file.hpp"

namespace scp::drivers::replay {
namespace {

using testing::TraceFile;

TEST(ReplayDriver, ReturnsRowsAsRecordedThenEndOfData) {
  const TraceFile f("t,x,xdot,T,V\n100.5,1e-6,,30,1\n100.75,2e-6,,31,2\n101.0,3e-6,,32,3\n");
  ReplayDriver d(f.path());
  d.open();
  EXPECT_EQ(d.name(), "replay");
  EXPECT_EQ(d.period(), 0.25);
  EXPECT_EQ(d.size(), 3u);
  Sample out;
  const double expected_t[3] = {100.5, 100.75, 101.0};
  for (int i = 0; i < 3; ++i) {
    double next = 0.0;
    ASSERT_TRUE(d.next_time(next));
    EXPECT_EQ(next, expected_t[i]);
    ASSERT_EQ(d.read({i * 0.25, 0.25}, out).status, IoStatus::ok);
    EXPECT_EQ(out.t, expected_t[i]);
    EXPECT_EQ(out.x, (i + 1) * 1e-6);
    EXPECT_TRUE(std::isnan(out.xdot));
    EXPECT_EQ(out.temperature, 30.0 + i);
    EXPECT_EQ(out.voltage, 1.0 + i);
    EXPECT_EQ(d.write_voltage(9.0).status, IoStatus::ok);
  }
  EXPECT_EQ(d.read({0.75, 0.25}, out).status, IoStatus::end_of_data);
  EXPECT_EQ(d.read({1.0, 0.25}, out).status, IoStatus::end_of_data);
  d.safe_state();
  d.safe_state();
  EXPECT_EQ(d.stats().reads, 3u);
  EXPECT_EQ(d.stats().writes, 3u);
  EXPECT_EQ(d.safe_states(), 2u);
  d.open();  // rewinds
  ASSERT_EQ(d.read({0.0, 0.25}, out).status, IoStatus::ok);
  EXPECT_EQ(out.temperature, 30.0);
}

TEST(ReplayDriver, BadFileIsADriverErrorWithTheLine) {
  const TraceFile f("t,x,xdot,T,V\n0,0,0,25,0\n0.001,zz,0,25,0\n");
  try {
    ReplayDriver d(f.path());
    FAIL() << "no exception";
  } catch (const DriverError& e) {
    EXPECT_NE(std::string(e.what()).find(f.path() + ":3:"), std::string::npos) << e.what();
  }
}

TEST(ReplayDriver, RejectsTooShortTrace) {
  Trace t;
  t.rows.resize(1);
  t.period = 1e-3;
  EXPECT_THROW(ReplayDriver{t}, DriverError);
}

}  // namespace
}  // namespace scp::drivers::replay

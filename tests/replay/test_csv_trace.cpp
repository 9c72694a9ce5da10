#include <gtest/gtest.h>

#include <cmath>
#include <sstream>
#include <string>

#include "drivers/replay/csv_trace.hpp"
#include "tests/replay/trace_file.hpp"

namespace scp::drivers::replay {
namespace {

using testing::TraceFile;

// Loads `content` and returns the TraceError message ("" if it loaded).
std::string error_of(const std::string& content) {
  const TraceFile f(content);
  try {
    load_trace(f.path());
  } catch (const TraceError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(f.path()), std::string::npos) << msg;  // names the file
    return msg.substr(f.path().size());                       // ":LINE: ..."
  }
  return "";
}

TEST(CsvTrace, RoundTripAnyColumnOrderExtraColumnsAndNotMeasuredVelocity) {
  const TraceFile f(
      "# recorded by a test\n"
      "V,theta_hat1,T,x,t,xdot,eps1\n"
      "0,1,25,0,10.000,0,0\n"
      "1.5,2,25.25,-1.5e-6,10.001,-2e-4,0\r\n"  // CRLF line end
      "\n"
      "2.25,3,26.5,-3e-6,10.002,,0\n"  // blank xdot = not measured
      "3.2,4,nan,+1e-7,10.003,nan,1\n");
  const Trace t = load_trace(f.path());
  ASSERT_EQ(t.rows.size(), 4u);
  EXPECT_NEAR(t.period, 0.001, 1e-15);
  EXPECT_EQ(t.rows[0].t, 10.0);
  EXPECT_EQ(t.rows[1].t, 10.001);
  EXPECT_EQ(t.rows[1].x, -1.5e-6);
  EXPECT_EQ(t.rows[1].xdot, -2e-4);
  EXPECT_EQ(t.rows[1].temperature, 25.25);
  EXPECT_EQ(t.rows[1].voltage, 1.5);
  EXPECT_TRUE(std::isnan(t.rows[2].xdot));
  EXPECT_EQ(t.rows[2].voltage, 2.25);
  EXPECT_TRUE(std::isnan(t.rows[3].xdot));
  EXPECT_TRUE(std::isnan(t.rows[3].temperature));  // loaded as-is, the loop's safety decides
  EXPECT_EQ(t.rows[3].x, 1e-7);
}

TEST(CsvTrace, VoltageSinceIsReadWhenRecordedAndBlankMeansTheWholeInterval) {
  const TraceFile f(
      "t,x,xdot,T,V,V_since\n"
      "0.010,0,0,25,0,\n"
      "0.020,0,0,25,1.5,0.0147\n"
      "0.030,0,0,25,1.5,\n");
  const Trace t = load_trace(f.path());
  ASSERT_EQ(t.rows.size(), 3u);
  EXPECT_TRUE(std::isinf(t.rows[0].voltage_since) && t.rows[0].voltage_since < 0.0);
  EXPECT_EQ(t.rows[1].voltage_since, 0.0147);
  EXPECT_TRUE(std::isinf(t.rows[2].voltage_since) && t.rows[2].voltage_since < 0.0);
  // Without the column every row has the whole interval.
  const TraceFile plain("t,x,xdot,T,V\n0,0,0,25,0\n0.01,0,0,25,1\n");
  EXPECT_TRUE(std::isinf(load_trace(plain.path()).rows[1].voltage_since));
}

TEST(CsvTrace, VoltageSinceAfterItsSampleOrUnreadableNamesLineAndColumn) {
  std::string msg = error_of("t,x,xdot,T,V,V_since\n0,0,0,25,0,\n0.01,0,0,25,1,0.02\n");
  EXPECT_NE(msg.find(":3:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("column 'V_since' (field 6)"), std::string::npos) << msg;
  EXPECT_NE(msg.find("after the row's t"), std::string::npos) << msg;
  msg = error_of("t,x,xdot,T,V,V_since\n0,0,0,25,0,\n0.01,0,0,25,1,inf\n");
  EXPECT_NE(msg.find("column 'V_since'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("leave it blank"), std::string::npos) << msg;
  msg = error_of("t,x,xdot,T,V,V_since,V_since\n0,0,0,25,0,,\n0.01,0,0,25,1,,\n");
  EXPECT_NE(msg.find("appears twice"), std::string::npos) << msg;
}

TEST(CsvTrace, HeaterCurrentIsReadWhenRecordedAndBlankMeansNotMeasured) {
  const TraceFile f(
      "t,x,xdot,T,V,I\n"
      "0.010,0,0,25,0,\n"
      "0.020,0,0,25,1.5,0.75\n"
      "0.030,0,0,25,1.5,nan\n"
      "0.040,0,0,25,1.5,-inf\n");
  const Trace t = load_trace(f.path());
  ASSERT_EQ(t.rows.size(), 4u);
  EXPECT_TRUE(std::isnan(t.rows[0].current));
  EXPECT_EQ(t.rows[1].current, 0.75);
  EXPECT_TRUE(std::isnan(t.rows[2].current));
  // Loaded as-is, like x, T and V: the loop's safety check faults on it.
  EXPECT_TRUE(std::isinf(t.rows[3].current) && t.rows[3].current < 0.0);
  // Without the column the current is not measured.
  const TraceFile plain("t,x,xdot,T,V\n0,0,0,25,0\n0.01,0,0,25,1\n");
  EXPECT_TRUE(std::isnan(load_trace(plain.path()).rows[1].current));
}

TEST(CsvTrace, UnreadableCurrentNamesLineAndColumn) {
  std::string msg = error_of("t,x,xdot,T,V,I\n0,0,0,25,0,0\n0.01,0,0,25,1,1,5\n");
  EXPECT_NE(msg.find(":3:"), std::string::npos) << msg;  // one field too many
  msg = error_of("t,x,xdot,T,V,I\n0,0,0,25,0,0\n0.01,0,0,25,1,1.2A\n");
  EXPECT_NE(msg.find(":3:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("column 'I' (field 6)"), std::string::npos) << msg;
  EXPECT_NE(msg.find("current"), std::string::npos) << msg;
  msg = error_of("t,x,xdot,T,V,I,I\n0,0,0,25,0,,\n0.01,0,0,25,1,,\n");
  EXPECT_NE(msg.find("appears twice"), std::string::npos) << msg;
}

TEST(CsvTrace, InfinityLoadedAsIs) {
  const TraceFile f("t,x,xdot,T,V\n0,0,0,25,0\n0.5,inf,0,25,-inf\n");
  const Trace t = load_trace(f.path());
  EXPECT_TRUE(std::isinf(t.rows[1].x));
  EXPECT_TRUE(std::isinf(t.rows[1].voltage));
  EXPECT_EQ(t.period, 0.5);
}

TEST(CsvTrace, MissingColumn) {
  const std::string e = error_of("t,x,T,V\n0,0,25,0\n1,0,25,0\n");
  EXPECT_EQ(e.rfind(":1:", 0), 0u) << e;
  EXPECT_NE(e.find("missing column 'xdot'"), std::string::npos) << e;
}

TEST(CsvTrace, UnparsableNumberNamesLineAndColumn) {
  const std::string e = error_of("t,x,xdot,T,V\n0,0,0,25,0\n0.001,1,5e-3,0,25,0\n");
  EXPECT_EQ(e.rfind(":3:", 0), 0u) << e;  // wrong field count first
  EXPECT_NE(e.find("6 fields"), std::string::npos) << e;
  const std::string e2 = error_of("t,x,xdot,T,V\n0,0,0,25,0\n0.001,1,5e-3,25,0\n0.002,0,0,2 5,0\n");
  EXPECT_EQ(e2.rfind(":4:", 0), 0u) << e2;
  EXPECT_NE(e2.find("column 'T' (field 4)"), std::string::npos) << e2;
  EXPECT_NE(e2.find("'2 5'"), std::string::npos) << e2;
  // A decimal comma (some locales) is not a number here.
  const std::string e3 = error_of("t;x;xdot;T;V\n");
  EXPECT_NE(e3.find("missing column"), std::string::npos) << e3;
}

TEST(CsvTrace, EmptyFieldOutsideXdot) {
  const std::string e = error_of("t,x,xdot,T,V\n0,0,0,25,0\n0.001,,0,25,0\n");
  EXPECT_EQ(e.rfind(":3:", 0), 0u) << e;
  EXPECT_NE(e.find("column 'x'"), std::string::npos) << e;
  EXPECT_NE(e.find("empty"), std::string::npos) << e;
}

TEST(CsvTrace, EmptyFile) {
  EXPECT_NE(error_of("").find("empty file"), std::string::npos);
  EXPECT_NE(error_of("\n# only a comment\n").find("empty file"), std::string::npos);
}

TEST(CsvTrace, FewerThanTwoRows) {
  const std::string e = error_of("t,x,xdot,T,V\n0,0,0,25,0\n");
  EXPECT_NE(e.find("only 1 data row"), std::string::npos) << e;
  EXPECT_NE(e.find("at least 2"), std::string::npos) << e;
}

TEST(CsvTrace, TimeNotIncreasing) {
  const std::string e = error_of("t,x,xdot,T,V\n0,0,0,25,0\n0.001,0,0,25,0\n0.001,0,0,25,0\n");
  EXPECT_EQ(e.rfind(":4:", 0), 0u) << e;
  EXPECT_NE(e.find("(line 3)"), std::string::npos) << e;
  const std::string e2 = error_of("t,x,xdot,T,V\n0,0,0,25,0\nnan,0,0,25,0\n");
  EXPECT_EQ(e2.rfind(":3:", 0), 0u) << e2;
  EXPECT_NE(e2.find("not finite"), std::string::npos) << e2;
}

// A real-time recording has gaps (missed periods, a fault) and jitter: they are replayed as the
// live estimator took them, not refused.
TEST(CsvTrace, GapsAreKeptAndCounted) {
  std::string csv = "t,x,xdot,T,V\n";
  for (int k = 0; k < 10; ++k) {
    const double t = k < 6 ? k * 0.001 : (k + 30) * 0.001;  // 30 periods missing after t = 0.005
    csv += std::to_string(t) + ",0,0,25,0\n";
  }
  std::istringstream in(csv);
  const Trace trace = parse_trace(in, "mem");
  EXPECT_EQ(trace.rows.size(), 10u);
  EXPECT_NEAR(trace.period, 0.001, 1e-12);
  EXPECT_EQ(trace.gaps, 1u);
  EXPECT_NEAR(trace.max_step, 0.031, 1e-9);
  EXPECT_EQ(trace.rows[6].t, 0.036);
}

TEST(CsvTrace, SeveralFilesAreOneTraceInTimeOrder) {
  const testing::TraceFile a("t,x,xdot,T,V\n0,0,0,25,0\n0.001,0,0,25,0\n");
  const testing::TraceFile b(
      "t,x,xdot,T,V\n# 3 rows dropped here\n0.005,0,0,25,0\n0.006,0,0,25,0\n");
  const Trace trace = load_traces({a.path(), b.path()});
  EXPECT_EQ(trace.rows.size(), 4u);
  EXPECT_EQ(trace.files.size(), 2u);
  EXPECT_EQ(trace.gaps, 1u);
  try {
    load_traces({b.path(), a.path()});
    FAIL() << "no exception";
  } catch (const TraceError& e) {
    const std::string what = e.what();
    EXPECT_EQ(what.rfind(a.path() + ": the first row's time 0", 0), 0u) << what;
    EXPECT_NE(what.find(b.path()), std::string::npos) << what;
  }
}

// The daemon stopped just after a rotation: the last file holds one row, or only the header.
TEST(CsvTrace, AFileOfOneRowOrNoneInARotatedRecording) {
  const testing::TraceFile a("t,x,xdot,T,V\n0,0,0,25,0\n0.001,0,0,25,0\n");
  const testing::TraceFile b("t,x,xdot,T,V\n0.002,0,0,25,0\n");
  const testing::TraceFile c("t,x,xdot,T,V\n");
  const Trace trace = load_traces({a.path(), b.path(), c.path()});
  EXPECT_EQ(trace.rows.size(), 3u);
  EXPECT_EQ(trace.files.size(), 3u);
  // Alone, a single row still cannot be replayed.
  EXPECT_THROW(load_traces({b.path()}), TraceError);
  EXPECT_THROW(load_traces({b.path(), c.path()}), TraceError);
}

TEST(CsvTrace, MissingFile) {
  try {
    load_trace("/nonexistent/dir/trace.csv");
    FAIL() << "no exception";
  } catch (const TraceError& e) {
    EXPECT_NE(std::string(e.what()).find("cannot open"), std::string::npos);
  }
}

}  // namespace
}  // namespace scp::drivers::replay

// scp-benchsim's files: read by the replay reader as written, the daemon's own simulated bench
// where the conventions agree, exact on a switching voltage, accurate at the default sub-step.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "drivers/replay/csv_trace.hpp"
#include "drivers/sim/sim_driver.hpp"
#include "excitation/excitation.hpp"
#include "tests/benchsim/switching_excitation.hpp"
#include "tools/benchsim/bench_file.hpp"

namespace scp::tools::benchsim {
namespace {

std::string make(const BenchFile& f) {
  std::ostringstream out;
  write_bench_file(f, out);
  return out.str();
}

drivers::replay::Trace replay(const std::string& text) {
  std::istringstream in(text);
  return drivers::replay::parse_trace(in, "bench.csv");
}

// The file's own fields, split by hand: the header and each row's text.
struct Table {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
  std::size_t column(const std::string& name) const {
    return static_cast<std::size_t>(std::find(header.begin(), header.end(), name) - header.begin());
  }
  double at(std::size_t row, const std::string& name) const {
    return std::stod(rows[row][column(name)]);
  }
};

Table split(const std::string& text) {
  Table t;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::vector<std::string> fields;
    std::size_t start = 0;
    for (;;) {
      const auto comma = line.find(',', start);
      fields.push_back(line.substr(start, comma == std::string::npos ? comma : comma - start));
      if (comma == std::string::npos) break;
      start = comma + 1;
    }
    (t.header.empty() ? t.header : t.rows.emplace_back()) = fields;
  }
  return t;
}

BenchFile short_file(double seconds) {
  BenchFile f = default_bench_file();
  f.duration_s = seconds;
  return f;
}

TEST(BenchFile, ColumnsRoundTripThroughTheReplayReader) {
  BenchFile f = short_file(2.0);
  f.timing = VoltageTiming::dac_before;
  apply_noise_level("N3", f.sim);
  f.sim.measure_current = true;
  f.sim.noise_current = 1e-3;
  f.sim.seed = 9;
  const std::string text = make(f);
  const drivers::replay::Trace trace = replay(text);
  const Table table = split(text);
  ASSERT_EQ((std::vector<std::string>{"t", "x", "xdot", "T", "V", "V_since", "I"}), table.header);
  ASSERT_EQ(trace.rows.size(), 2001u);
  ASSERT_EQ(table.rows.size(), trace.rows.size());
  EXPECT_NEAR(trace.period, 1e-3, 1e-15);
  EXPECT_EQ(trace.gaps, 0u);
  for (std::size_t k = 0; k < trace.rows.size(); ++k) {
    const drivers::Sample& s = trace.rows[k];
    ASSERT_EQ(s.t, static_cast<double>(k) * 1e-3) << k;
    ASSERT_EQ(s.x, table.at(k, "x")) << k;
    ASSERT_EQ(s.temperature, table.at(k, "T")) << k;
    ASSERT_EQ(s.voltage, table.at(k, "V")) << k;
    ASSERT_TRUE(std::isnan(s.xdot)) << k;  // N3: no velocity sensor, left blank
    ASSERT_TRUE(table.rows[k][table.column("xdot")].empty());
    ASSERT_EQ(s.voltage_since, -std::numeric_limits<double>::infinity());  // the whole interval
    ASSERT_TRUE(std::isfinite(table.at(k, "I")));
    ASSERT_EQ(s.current, table.at(k, "I")) << k;
  }
}

// With the daemon's convention a file is the daemon's simulated bench: the same commands, the
// same noise draws, the plant integrated otherwise (all states by RK4 against the exact thermal
// solution) but to the same values within rounding.
TEST(BenchFile, DacBeforeIsTheDaemonsSimulatedBench) {
  BenchFile f = short_file(20.0);
  f.timing = VoltageTiming::dac_before;
  apply_noise_level("N1", f.sim);
  f.sim.seed = 5;
  const drivers::replay::Trace trace = replay(make(f));
  drivers::sim::SimDriver sim(f.sim);
  sim.open();
  const excitation::Excitation excitation(f.excitation);
  double max_x = 0.0, err_x = 0.0, err_xdot = 0.0, err_t = 0.0;
  for (std::size_t k = 0; k < trace.rows.size(); ++k) {
    const double t = static_cast<double>(k) * f.period_s;
    drivers::Sample s;
    ASSERT_EQ(sim.read({t, f.period_s}, s).status, drivers::IoStatus::ok);
    const drivers::Sample& row = trace.rows[k];
    ASSERT_EQ(row.voltage, s.voltage) << k;
    max_x = std::max(max_x, std::abs(s.x));
    err_x = std::max(err_x, std::abs(row.x - s.x));
    err_xdot = std::max(err_xdot, std::abs(row.xdot - s.xdot));
    err_t = std::max(err_t, std::abs(row.temperature - s.temperature));
    sim.write_voltage(excitation.voltage(t));
  }
  ASSERT_GT(max_x, 1e-4);
  EXPECT_LT(err_x, 1e-12 * max_x);
  EXPECT_LT(err_xdot, 1e-12 * max_x);
  EXPECT_LT(err_t, 1e-10);
}

TEST(BenchFile, DacAfterLogsTheSameRunOneRowEarlier) {
  BenchFile f = short_file(5.0);
  f.sim.deviations.resistance_tempco = 0.004;
  f.timing = VoltageTiming::dac_before;
  const drivers::replay::Trace before = replay(make(f));
  f.timing = VoltageTiming::dac_after;
  const std::string after_text = make(f);
  EXPECT_EQ(split(after_text).header, (std::vector<std::string>{"t", "x", "xdot", "T", "V"}));
  const drivers::replay::Trace after = replay(after_text);
  ASSERT_EQ(before.rows.size(), after.rows.size());
  EXPECT_EQ(before.rows[0].voltage, 0.0);  // nothing was applied before t = 0
  for (std::size_t k = 0; k + 1 < after.rows.size(); ++k) {
    ASSERT_EQ(after.rows[k].voltage, before.rows[k + 1].voltage) << k;
    ASSERT_EQ(after.rows[k].x, before.rows[k].x) << k;
    ASSERT_EQ(after.rows[k].temperature, before.rows[k].temperature) << k;
  }
}

// A voltage of two levels only (offset ± PRBS, bits of 12.3 ms switching between samples): the
// thermal equation is then exact as a chain of exponentials over the pieces between switches.
TEST(BenchFile, ContinuousSwitchingVoltageLandsOnEverySwitch) {
  BenchFile f = short_file(3.0);
  f.excitation = {};
  f.excitation.offset = 1.5;
  f.excitation.prbs.amplitude = 1.0;
  f.excitation.prbs.bit_period_s = 0.0123;
  const drivers::replay::Trace trace = replay(make(f));
  const excitation::Excitation v(f.excitation);
  const auto& p = f.sim.plant;
  const double a = p.lambda / p.Cth, bit = f.excitation.prbs.bit_period_s;
  double tbar = 0.0, t = 0.0, max_err = 0.0;
  long next_bit = 1;
  for (std::size_t k = 1; k < trace.rows.size(); ++k) {
    const double sample = static_cast<double>(k) * f.period_s;
    while (t < sample) {
      const double end = std::min(sample, static_cast<double>(next_bit) * bit);
      const double volts = v.voltage(0.5 * (t + end));
      const double ss = volts * volts / (p.R * p.lambda);
      tbar = ss + (tbar - ss) * std::exp(-a * (end - t));
      if (end < sample) ++next_bit;
      t = end;
    }
    max_err = std::max(max_err, std::abs(trace.rows[k].temperature - 25.0 - tbar));
  }
  // A step straddling a switch would be off by about h·ΔV²/Cth = 1e-4 °C at each of the 243.
  EXPECT_LT(max_err, 1e-11);
}

TEST(BenchFile, HalvingTheSubstepChangesNothingThatMatters) {
  BenchFile f = short_file(10.0);
  f.excitation = switching_excitation();
  auto& d = f.sim.deviations;
  d = {0.0059, 0.003, 0.005, 1.0, 2.0, 0.3};
  f.sim.substeps = 10;
  const drivers::replay::Trace coarse = replay(make(f));
  f.sim.substeps = 20;
  const drivers::replay::Trace fine = replay(make(f));
  double max_x = 0.0, err_x = 0.0, err_t = 0.0;
  for (std::size_t k = 0; k < fine.rows.size(); ++k) {
    max_x = std::max(max_x, std::abs(fine.rows[k].x));
    err_x = std::max(err_x, std::abs(fine.rows[k].x - coarse.rows[k].x));
    err_t = std::max(err_t, std::abs(fine.rows[k].temperature - coarse.rows[k].temperature));
  }
  ASSERT_GT(max_x, 1e-5);
  EXPECT_LT(err_x, 1e-11 * max_x);
  EXPECT_LT(err_t, 1e-10);
}

TEST(BenchFile, CurrentIsTheAppliedVoltageOverTheHotResistance) {
  BenchFile f = short_file(30.0);
  f.timing = VoltageTiming::dac_before;  // each row's V is the one applied just before it
  f.sim.deviations.resistance_tempco = 0.004;
  f.sim.measure_current = true;
  const std::string text = make(f);
  const Table table = split(text);
  double max_err = 0.0;
  for (std::size_t k = 0; k < table.rows.size(); ++k) {
    const double tbar = table.at(k, "T") - 25.0;
    const double r = f.sim.plant.R * (1.0 + 0.004 * tbar);
    max_err = std::max(max_err, std::abs(table.at(k, "I") * r - table.at(k, "V")));
  }
  EXPECT_LT(max_err, 1e-12);
  EXPECT_GT(table.at(table.rows.size() - 1, "T"), 40.0);  // hot enough for R to have moved
}

TEST(BenchFile, SensorOffsetsAndContinuousVoltageReachTheRows) {
  BenchFile f = short_file(1.0);
  f.sim.x_zero = 5e-5;
  f.sim.deviations.ambient_offset_c = -2.0;
  const drivers::replay::Trace trace = replay(make(f));
  EXPECT_EQ(trace.rows[0].x, 5e-5);
  EXPECT_EQ(trace.rows[0].temperature, 23.0);
  const excitation::Excitation v(f.excitation);
  for (const drivers::Sample& s : trace.rows) ASSERT_EQ(s.voltage, v.voltage(s.t)) << s.t;
}

TEST(BenchFile, InvalidSettingsNameTheField) {
  const auto error = [](const BenchFile& f) -> std::string {
    try {
      make(f);
    } catch (const std::exception& e) {
      return e.what();
    }
    return "";
  };
  BenchFile f = short_file(1.0);
  f.sim.deviations.temperature_lag_s = 1e-4;
  EXPECT_NE(error(f).find("sim.sensor.temperature_lag_s"), std::string::npos) << error(f);
  f = short_file(1.0);
  f.period_s = 0.0;
  EXPECT_NE(error(f).find("period"), std::string::npos) << error(f);
  f = short_file(1.0);
  f.excitation.prbs.bit_period_s = -1.0;
  f.excitation.prbs.amplitude = 1.0;
  EXPECT_NE(error(f).find("excitation.prbs.bit_period_s"), std::string::npos) << error(f);
  EXPECT_THROW(apply_noise_level("N9", f.sim), std::invalid_argument);
  EXPECT_THROW(parse_voltage_timing("zoh"), std::invalid_argument);
  EXPECT_EQ(error(short_file(0.01)), "");
}

}  // namespace
}  // namespace scp::tools::benchsim

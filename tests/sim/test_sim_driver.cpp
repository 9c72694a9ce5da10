#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "drivers/sim/sim_driver.hpp"

namespace scp::drivers::sim {
namespace {

constexpr double kPeriod = 1e-3;

CycleTime at(int k) {
  return {k * kPeriod, kPeriod};
}

std::string error_of(const SimSettings& s) {
  try {
    SimDriver d(s);
  } catch (const DriverError& e) {
    return e.what();
  }
  return "";
}

TEST(SimDriver, FirstReadIsAtRest) {
  SimSettings s;
  s.ambient_c = 22.5;
  SimDriver d(s);
  d.open();
  Sample out;
  ASSERT_EQ(d.read(at(0), out).status, IoStatus::ok);
  EXPECT_EQ(out.t, 0.0);
  EXPECT_EQ(out.x, 0.0);
  EXPECT_EQ(out.xdot, 0.0);
  EXPECT_EQ(out.temperature, 22.5);
  EXPECT_EQ(out.voltage, 0.0);
}

TEST(SimDriver, HeldVoltageHeatsAsClosedForm) {
  SimSettings s;
  SimDriver d(s);
  d.open();
  Sample out;
  const double v = 2.0;
  for (int k = 0; k <= 10000; ++k) {
    ASSERT_EQ(d.read(at(k), out).status, IoStatus::ok);
    if (k > 0) {
      ASSERT_EQ(out.voltage, v);  // the voltage over the interval that ends at t
    }
    d.write_voltage(v);
  }
  const double t = 10.0;
  const double tbar = v * v / (1.0 * 0.054) * (1.0 - std::exp(-0.054 * t / 0.909));
  EXPECT_NEAR(out.t, t, 1e-12);
  EXPECT_NEAR(out.temperature, 25.0 + tbar, 1e-9);
  EXPECT_EQ(d.stats().reads, 10001u);
  EXPECT_EQ(d.stats().writes, 10001u);
}

TEST(SimDriver, SafeStateCommandsZero) {
  SimDriver d(SimSettings{});
  Sample out;
  d.read(at(0), out);
  d.write_voltage(3.0);
  d.safe_state();
  d.read(at(1), out);
  EXPECT_EQ(out.voltage, 0.0);
  EXPECT_EQ(out.temperature, 25.0);  // no heating happened
  EXPECT_EQ(d.write_voltage(std::nan("")).status, IoStatus::error);
  EXPECT_EQ(d.command(), 0.0);
}

TEST(SimDriver, VelocityNotMeasured) {
  SimSettings s;
  s.measure_xdot = false;
  SimDriver d(s);
  Sample out;
  d.read(at(0), out);
  EXPECT_TRUE(std::isnan(out.xdot));
  EXPECT_EQ(out.x, 0.0);
}

TEST(SimDriver, NoiseIsSeededAndHasTheConfiguredStdDev) {
  SimSettings s;
  s.noise_x = 1e-6;
  s.noise_xdot = 2e-6;
  s.noise_temperature = 0.1;
  s.noise_voltage = 0.01;
  s.seed = 42;
  SimDriver a(s), b(s);
  s.seed = 43;
  SimDriver c(s);
  // At 0 V the plant stays exactly at rest, so the samples are pure noise.
  const int n = 20000;
  double sum[4] = {}, sq[4] = {};
  bool differs = false;
  for (int k = 0; k < n; ++k) {
    Sample sa, sb, sc;
    a.read(at(k), sa);
    b.read(at(k), sb);
    c.read(at(k), sc);
    ASSERT_EQ(sa.x, sb.x);
    ASSERT_EQ(sa.temperature, sb.temperature);
    differs = differs || sa.x != sc.x;
    const double v[4] = {sa.x, sa.xdot, sa.temperature - 25.0, sa.voltage};
    for (int i = 0; i < 4; ++i) {
      sum[i] += v[i];
      sq[i] += v[i] * v[i];
    }
  }
  EXPECT_TRUE(differs);
  const double sd[4] = {1e-6, 2e-6, 0.1, 0.01};
  for (int i = 0; i < 4; ++i) {
    const double mean = sum[i] / n;
    const double stddev = std::sqrt(sq[i] / n - mean * mean);
    // Standard error of the sample std dev is σ/√(2n) ≈ 0.5 %; of the mean σ/√n ≈ 0.7 %.
    EXPECT_NEAR(stddev, sd[i], 0.03 * sd[i]) << i;
    EXPECT_NEAR(mean, 0.0, 0.04 * sd[i]) << i;
  }
}

TEST(SimDriver, TrueThetaFollowsDrift) {
  SimSettings s;
  s.drift.k = 0.1;     // +10 %/h
  s.drift.Cth = -0.5;  // −50 %/h
  SimDriver d(s);
  std::array<double, 6> th{};
  ASSERT_TRUE(d.true_theta(0.0, th));
  const double expected0[6] = {1247, 0.8, 1813, 0.1, 0.054 / 0.909, 1.0 / 0.909};
  for (int i = 0; i < 6; ++i) EXPECT_NEAR(th[i], expected0[i], 1e-12 * expected0[i]) << i;
  ASSERT_TRUE(d.true_theta(3600.0, th));
  const double expected1[6] = {
      1247, 0.8, 1813 * 1.1, 0.1, 0.054 / (0.909 * 0.5), 1.0 / (0.909 * 0.5)};
  for (int i = 0; i < 6; ++i) EXPECT_NEAR(th[i], expected1[i], 1e-12 * expected1[i]) << i;
  ASSERT_TRUE(d.true_theta(1800.0, th));
  EXPECT_NEAR(th[2], 1813 * 1.05, 1e-9);
}

TEST(SimDriver, ValidationNamesTheField) {
  SimSettings s;
  s.substeps = 0;
  EXPECT_NE(error_of(s).find("sim.substeps"), std::string::npos) << error_of(s);
  s = {};
  s.plant.m = -0.1;
  EXPECT_NE(error_of(s).find("sim.plant.m"), std::string::npos);
  s = {};
  s.plant.lambda = std::nan("");
  EXPECT_NE(error_of(s).find("sim.plant.lambda"), std::string::npos);
  s = {};
  s.noise_temperature = -1;
  EXPECT_NE(error_of(s).find("sim.noise.temperature"), std::string::npos);
  s = {};
  s.drift.b = std::numeric_limits<double>::infinity();
  EXPECT_NE(error_of(s).find("sim.drift.b"), std::string::npos);
  s = {};
  s.fault = "melted";
  const std::string e = error_of(s);
  EXPECT_NE(e.find("sim.fault.kind"), std::string::npos);
  EXPECT_NE(e.find("nan_temperature"), std::string::npos);  // lists the remedy
  s = {};
  s.step_parameter = "Rth";  // not a parameter: it would never step
  const std::string step = error_of(s);
  EXPECT_NE(step.find("sim.step.parameter"), std::string::npos) << step;
  EXPECT_NE(step.find("alpha2"), std::string::npos) << step;  // lists the remedy
  s = {};
  s.fault_start_s = -1;
  EXPECT_NE(error_of(s).find("sim.fault.start_s"), std::string::npos);
  EXPECT_EQ(error_of(SimSettings{}), "");
}

TEST(SimDriver, StepMultipliesTheNamedParameterOnceAtItsTime) {
  SimSettings s;
  s.step_parameter = "lambda";
  s.step_at_s = 0.5;
  s.step_factor = 1.1;
  SimDriver d(s);
  d.open();
  Sample out;
  ASSERT_EQ(d.read(at(400), out).status, IoStatus::ok);
  EXPECT_EQ(d.plant().nominal_params().lambda, s.plant.lambda);
  ASSERT_EQ(d.read(at(600), out).status, IoStatus::ok);
  EXPECT_DOUBLE_EQ(d.plant().nominal_params().lambda, s.plant.lambda * 1.1);
  EXPECT_EQ(d.plant().nominal_params().R, s.plant.R);
  ASSERT_EQ(d.read(at(900), out).status, IoStatus::ok);
  EXPECT_DOUBLE_EQ(d.plant().nominal_params().lambda, s.plant.lambda * 1.1);  // once
}

// Runs 3 s at 3 V with the fault in [1, 1.5) s; returns each read's status and sample.
struct FaultRun {
  std::vector<IoResult> results;
  std::vector<Sample> samples;
};
FaultRun run_with_fault(const std::string& fault, double duration = 0.5) {
  SimSettings s;
  s.fault = fault;
  s.fault_start_s = 1.0;
  s.fault_duration_s = duration;
  SimDriver d(s);
  d.open();
  FaultRun r;
  for (int k = 0; k <= 3000; ++k) {
    Sample out;
    r.results.push_back(d.read(at(k), out));
    r.samples.push_back(out);
    d.write_voltage(3.0);
  }
  return r;
}

TEST(SimDriver, FaultNanTemperature) {
  const FaultRun r = run_with_fault("nan_temperature");
  EXPECT_TRUE(std::isfinite(r.samples[999].temperature));
  EXPECT_TRUE(std::isnan(r.samples[1000].temperature));
  EXPECT_TRUE(std::isnan(r.samples[1499].temperature));
  EXPECT_TRUE(std::isfinite(r.samples[1500].temperature));
  EXPECT_TRUE(std::isfinite(r.samples[1200].x));
}

TEST(SimDriver, FaultTemperatureOutOfRange) {
  const FaultRun r = run_with_fault("temperature_out_of_range");
  EXPECT_LT(r.samples[999].temperature, 100.0);
  EXPECT_EQ(r.samples[1000].temperature, 400.0);
  EXPECT_LT(r.samples[1500].temperature, 100.0);
}

TEST(SimDriver, FaultStuckPosition) {
  const FaultRun r = run_with_fault("stuck_position");
  // The actuator keeps contracting (x decreasing under 3 V), the sensor does not.
  EXPECT_LT(r.samples[999].x, r.samples[500].x);
  for (int k = 1000; k < 1500; ++k) ASSERT_EQ(r.samples[k].x, r.samples[999].x) << k;
  EXPECT_LT(r.samples[1500].x, r.samples[999].x);
}

TEST(SimDriver, FaultInfPosition) {
  const FaultRun r = run_with_fault("inf_position");
  EXPECT_TRUE(std::isfinite(r.samples[999].x));
  EXPECT_TRUE(std::isinf(r.samples[1000].x));
  EXPECT_GT(r.samples[1499].x, 0.0);
  EXPECT_TRUE(std::isfinite(r.samples[1500].x));
  EXPECT_TRUE(std::isfinite(r.samples[1200].temperature));
}

TEST(SimDriver, FaultStuckSensorFreezesXAndT) {
  const FaultRun r = run_with_fault("stuck_sensor");
  // Under 3 V the actuator heats and contracts; the dead sensor repeats its last reading.
  EXPECT_GT(r.samples[999].temperature, r.samples[500].temperature);
  for (int k = 1000; k < 1500; ++k) {
    ASSERT_EQ(r.samples[k].x, r.samples[999].x) << k;
    ASSERT_EQ(r.samples[k].temperature, r.samples[999].temperature) << k;
    ASSERT_EQ(r.samples[k].xdot, r.samples[999].xdot) << k;
  }
  EXPECT_GT(r.samples[1500].temperature, r.samples[999].temperature);
  EXPECT_LT(r.samples[1500].x, r.samples[999].x);
}

TEST(SimDriver, FaultReadErrorAndNoData) {
  const FaultRun e = run_with_fault("read_error");
  EXPECT_EQ(e.results[999].status, IoStatus::ok);
  EXPECT_EQ(e.results[1000].status, IoStatus::error);
  EXPECT_STREQ(e.results[1000].reason, "simulated sensor read error");
  EXPECT_EQ(e.results[1500].status, IoStatus::ok);
  const FaultRun n = run_with_fault("no_data", 0.0);  // forever
  EXPECT_EQ(n.results[999].status, IoStatus::ok);
  EXPECT_EQ(n.results[1000].status, IoStatus::no_data);
  EXPECT_EQ(n.results[3000].status, IoStatus::no_data);
}

TEST(SimDriver, PlantAdvancesThroughFaults) {
  // The physics is independent of what the sensor reports.
  const FaultRun clean = run_with_fault("none");
  const FaultRun faulty = run_with_fault("read_error");
  EXPECT_EQ(clean.samples[2000].temperature, faulty.samples[2000].temperature);
  EXPECT_EQ(clean.samples[2000].x, faulty.samples[2000].x);
}

}  // namespace
}  // namespace scp::drivers::sim

namespace scp::drivers::sim {
namespace {

TEST(SimDriver, FaultStallBlocksOnceForTheDuration) {
  SimSettings s;
  s.fault = "stall";
  s.fault_start_s = 0.002;
  s.fault_duration_s = 0.05;
  SimDriver d(s);
  Sample out;
  double longest = 0.0, total = 0.0;
  for (int k = 0; k < 100; ++k) {
    const auto t0 = std::chrono::steady_clock::now();
    ASSERT_EQ(d.read(at(k), out).status, IoStatus::ok);
    const double took =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (k == 2) {
      EXPECT_GE(took, 0.05);
    }
    longest = k == 2 ? longest : std::max(longest, took);
    total += took;
  }
  EXPECT_LT(longest, 0.02);  // no other read blocks
  EXPECT_LT(total, 0.5);
}

}  // namespace
}  // namespace scp::drivers::sim

// The simulated DAQ's view of a real bench (issue 28): the displacement sensor's zero, the true
// ambient, the heater-current channel and their validation.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "drivers/sim/sim_driver.hpp"

namespace scp::drivers::sim {
namespace {

constexpr double kPeriod = 1e-3;

std::string error_of(const SimSettings& s) {
  try {
    SimDriver d(s);
  } catch (const DriverError& e) {
    return e.what();
  }
  return "";
}

// Reads every period for `seconds` at `volts`; returns the last sample.
Sample run(SimDriver& d, double volts, double seconds) {
  Sample out;
  const int steps = static_cast<int>(std::lround(seconds / kPeriod));
  for (int k = 0; k <= steps; ++k) {
    EXPECT_EQ(d.read({k * kPeriod, kPeriod}, out).status, IoStatus::ok);
    d.write_voltage(volts);
  }
  return out;
}

TEST(SimSensors, ZeroAndAmbientOffsetShiftTheReadingsOnly) {
  SimSettings plain, shifted;
  shifted.x_zero = 50e-6;
  shifted.deviations.ambient_offset_c = -2.0;
  SimDriver a(plain), b(shifted);
  a.open();
  b.open();
  Sample sa, sb;
  ASSERT_EQ(b.read({0.0, kPeriod}, sb).status, IoStatus::ok);
  EXPECT_EQ(sb.x, 50e-6);           // at rest at the true ambient: x = 0, read as the zero
  EXPECT_EQ(sb.temperature, 23.0);  // the true ambient, 2 °C below the configured 25
  sa = run(a, 2.0, 5.0);
  sb = run(b, 2.0, 5.0);
  // An offset moves no physics: the same trajectory, read 50 µm and −2 °C off.
  EXPECT_EQ(a.plant().x(), b.plant().x());
  EXPECT_EQ(a.plant().tbar(), b.plant().tbar());
  EXPECT_NEAR(sb.x - sa.x, 50e-6, 1e-18);
  EXPECT_NEAR(sb.temperature - sa.temperature, -2.0, 1e-12);
  EXPECT_GT(sa.temperature, 30.0);
}

TEST(SimSensors, TemperatureIsAbsoluteThroughTheLag) {
  SimSettings prompt;
  prompt.ambient_c = 20.0;
  prompt.deviations.ambient_offset_c = 1.0;
  SimSettings lagging = prompt;
  lagging.deviations.temperature_lag_s = 0.3;
  SimDriver a(prompt), b(lagging);
  a.open();
  b.open();
  const Sample sa = run(a, 3.0, 2.0);
  const Sample sb = run(b, 3.0, 2.0);
  // Absolute: the configured ambient + the true ambient's offset + T̄.
  EXPECT_NEAR(sa.temperature, 21.0 + a.plant().tbar(), 1e-12);
  // Heating from rest at constant power, T̄ = T̄ss(1 − e^{−at}), a = λ/Cth; a first-order lag τ from
  // equilibrium trails it by T̄ss·aτ/(1 − aτ)·(e^{−at} − e^{−t/τ}) (about τ·dT̄/dt).
  const PlantParams& p = prompt.plant;
  const double rate = p.lambda / p.Cth, tau = 0.3, t = 2.0, tss = 9.0 / (p.R * p.lambda);
  const double trail =
      tss * rate * tau / (1.0 - rate * tau) * (std::exp(-rate * t) - std::exp(-t / tau));
  EXPECT_NEAR(sa.temperature - sb.temperature, trail, 1e-9 * trail);
}

// Coloured sensor noise (a filtered or drifting sensor, the white noise's counterpart): each
// channel's noise keeps its standard deviation and has the lag-one correlation exp(−Δ/τc) of a
// first-order Gauss–Markov process; with τc = 0 it is white and the samples are those of before.
double lag_one_correlation(const std::vector<double>& v, double* stddev) {
  double mean = 0.0;
  for (const double e : v) mean += e / static_cast<double>(v.size());
  double c0 = 0.0, c1 = 0.0;
  for (std::size_t i = 0; i < v.size(); ++i) {
    c0 += (v[i] - mean) * (v[i] - mean);
    if (i > 0) c1 += (v[i] - mean) * (v[i - 1] - mean);
  }
  *stddev = std::sqrt(c0 / static_cast<double>(v.size()));
  return c1 / c0;
}

TEST(SimSensors, ColouredNoiseKeepsItsDeviationAndHasTheConfiguredCorrelation) {
  SimSettings white;
  white.noise_x = 1e-6;
  white.noise_temperature = 0.1;
  SimSettings coloured = white;
  coloured.noise_correlation_s = 0.02;
  SimSettings quiet = white;
  quiet.noise_x = quiet.noise_temperature = 0.0;
  SimDriver w(white), c(coloured), q(quiet);
  w.open();
  c.open();
  q.open();
  std::vector<double> wx, cx, ct;
  for (int k = 0; k < 200000; ++k) {  // 200 s at rest: the noise alone, 10⁴ correlation times
    Sample sw, sc, sq;
    const CycleTime now{k * kPeriod, kPeriod};
    ASSERT_EQ(w.read(now, sw).status, IoStatus::ok);
    ASSERT_EQ(c.read(now, sc).status, IoStatus::ok);
    ASSERT_EQ(q.read(now, sq).status, IoStatus::ok);
    wx.push_back(sw.x - sq.x);
    cx.push_back(sc.x - sq.x);
    ct.push_back(sc.temperature - sq.temperature);
  }
  double sd_w = 0.0, sd_x = 0.0, sd_t = 0.0;
  const double rho_w = lag_one_correlation(wx, &sd_w);
  const double rho_x = lag_one_correlation(cx, &sd_x);
  const double rho_t = lag_one_correlation(ct, &sd_t);
  const double expected = std::exp(-kPeriod / 0.02);  // 0.951
  EXPECT_NEAR(rho_w, 0.0, 0.01);
  EXPECT_NEAR(rho_x, expected, 0.005);
  EXPECT_NEAR(rho_t, expected, 0.005);
  // σ of the mean of 10⁴ correlation times' worth of samples: a few %.
  EXPECT_NEAR(sd_w, 1e-6, 0.01e-6);
  EXPECT_NEAR(sd_x, 1e-6, 0.05e-6);
  EXPECT_NEAR(sd_t, 0.1, 0.005);
  coloured.noise_correlation_s = -1.0;
  EXPECT_NE(error_of(coloured).find("sim.noise.correlation_s"), std::string::npos);
}

TEST(SimSensors, CurrentFollowsTheHotResistance) {
  SimSettings s;
  s.deviations.resistance_tempco = 0.004;
  s.measure_current = true;
  SimDriver d(s);
  d.open();
  run(d, 2.5, 20.0);
  const double tbar = d.plant().tbar();
  ASSERT_GT(tbar, 30.0);
  // The current read at t flows from the voltage held over the interval before it.
  EXPECT_NEAR(d.current(), 2.5 / (s.plant.R * (1.0 + 0.004 * tbar)), 1e-12);
  SimSettings off;
  SimDriver no_channel(off);
  no_channel.open();
  run(no_channel, 2.5, 0.01);
  EXPECT_TRUE(std::isnan(no_channel.current()));
}

TEST(SimSensors, CurrentNoiseLeavesTheOtherChannelsSequence) {
  SimSettings s;
  s.noise_x = 1e-7;
  s.noise_temperature = 1e-3;
  s.noise_voltage = 1e-3;
  s.seed = 11;
  SimSettings with_current = s;
  with_current.measure_current = true;
  with_current.noise_current = 1e-3;
  SimDriver a(s), b(with_current);
  a.open();
  b.open();
  double sum = 0.0, sum2 = 0.0;
  const int n = 20000;
  for (int k = 0; k < n; ++k) {
    Sample sa, sb;
    a.read({k * kPeriod, kPeriod}, sa);
    b.read({k * kPeriod, kPeriod}, sb);
    ASSERT_EQ(sa.x, sb.x) << k;
    ASSERT_EQ(sa.temperature, sb.temperature) << k;
    ASSERT_EQ(sa.voltage, sb.voltage) << k;
    const double e = b.current() - b.plant().current(1.0 * (k > 0));
    sum += e;
    sum2 += e * e;
    a.write_voltage(1.0);
    b.write_voltage(1.0);
  }
  EXPECT_NEAR(sum / n, 0.0, 4.0 * 1e-3 / std::sqrt(n));
  EXPECT_NEAR(std::sqrt(sum2 / n), 1e-3, 0.03 * 1e-3);
}

TEST(SimSensors, ValidationNamesTheNewFields) {
  const auto named = [](SimSettings s, const char* key) {
    const std::string e = error_of(s);
    EXPECT_NE(e.find(key), std::string::npos) << key << ": " << e;
  };
  SimSettings s;
  s.deviations.resistance_tempco = 0.5;
  named(s, "sim.tempco.R");
  s = {};
  s.deviations.stiffness_softening = std::nan("");
  named(s, "sim.tempco.k_softening");
  s = {};
  s.deviations.cooling_tempco = -1;
  named(s, "sim.tempco.lambda");
  s = {};
  s.deviations.ambient_offset_c = 1e3;
  named(s, "sim.ambient.offset_c");
  s = {};
  s.deviations.ambient_drift_c_per_h = INFINITY;
  named(s, "sim.ambient.drift_c_per_h");
  s = {};
  s.deviations.temperature_lag_s = 1e-4;  // faster than an RK4 sub-step may follow
  named(s, "sim.sensor.temperature_lag_s");
  s = {};
  s.x_zero = 2.0;
  named(s, "sim.sensor.x_zero_m");
  s = {};
  s.noise_current = -1e-3;
  named(s, "sim.noise.current");
  s = {};
  s.deviations = {0.0059, 0.003, 0.005, -2.0, 2.0, 0.5};
  s.x_zero = 1e-3;
  s.measure_current = true;
  s.noise_current = 1e-3;
  EXPECT_EQ(error_of(s), "");
}

}  // namespace
}  // namespace scp::drivers::sim

// The plant's deviations from the paper's model (issue 28) against closed forms and limiting
// cases, and the paper's model itself unchanged bit for bit when every deviation is off.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "drivers/sim/plant.hpp"

namespace scp::drivers::sim {
namespace {

const PlantParams kTable;  // Table I

double paper_voltage(double t) {
  const double w1 = 2.0 * std::numbers::pi * 0.006, w2 = 2.0 * std::numbers::pi * 0.1;
  const double h = std::numbers::pi / 2.0;
  return 1.6 +
         0.4 * (std::sin(w1 * t - h) + std::sin(w1 * t) + std::sin(w2 * t) + std::sin(w2 * t - h));
}

// The plant's step as it was before the deviations existed (commit f7da94e), kept here verbatim
// as the reference for "off means unchanged".
struct LegacyPlant {
  PlantParams p;
  int substeps_per_ms = 20;
  double x = 0.0, xdot = 0.0, tbar = 0.0;

  void step(double voltage, double dt) {
    const double a = p.lambda / p.Cth;
    const double tbar_ss = voltage * voltage / (p.R * p.lambda);
    const double tbar0 = tbar;
    const double inv_m = 1.0 / p.m;
    auto accel = [&](double xx, double v, double tb) {
      return -((p.b + p.alpha1 * tb) * v + p.k * xx + p.alpha2 * tb) * inv_m;
    };
    const double n_real = std::ceil(dt * 1e3 * substeps_per_ms - 1e-9);
    const long n = static_cast<long>(std::clamp(n_real, 1.0, 1099511627776.0));
    const double h = dt / static_cast<double>(n);
    const double half_decay = std::exp(-0.5 * a * h);
    double dev = tbar0 - tbar_ss;
    double xx = x, v = xdot;
    for (long i = 0; i < n; ++i) {
      const double tb0 = tbar_ss + dev;
      dev *= half_decay;
      const double tbh = tbar_ss + dev;
      dev *= half_decay;
      const double tb1 = tbar_ss + dev;
      const double k1x = v, k1v = accel(xx, v, tb0);
      const double k2x = v + 0.5 * h * k1v, k2v = accel(xx + 0.5 * h * k1x, v + 0.5 * h * k1v, tbh);
      const double k3x = v + 0.5 * h * k2v, k3v = accel(xx + 0.5 * h * k2x, v + 0.5 * h * k2v, tbh);
      const double k4x = v + h * k3v, k4v = accel(xx + h * k3x, v + h * k3v, tb1);
      xx += h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x);
      v += h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
    }
    x = xx;
    xdot = v;
    tbar = tbar_ss + (tbar0 - tbar_ss) * std::exp(-a * dt);
  }
};

TEST(PlantDeviations, AllOffIsTheOldPlantBitForBit) {
  PlantDeviations off;
  off.ambient_offset_c = 3.0;  // shifts only the sensor's reading, never the dynamics
  Plant plant(kTable, 20, {}, off);
  LegacyPlant legacy{kTable};
  for (int k = 0; k < 20000; ++k) {
    const double v = paper_voltage(k * 1e-3);
    plant.step(v, 1e-3);
    legacy.step(v, 1e-3);
    ASSERT_EQ(plant.x(), legacy.x) << k;
    ASSERT_EQ(plant.xdot(), legacy.xdot) << k;
    ASSERT_EQ(plant.tbar(), legacy.tbar) << k;
  }
  EXPECT_EQ(plant.sensed_tbar(), plant.tbar() + 3.0);
  EXPECT_EQ(plant.resistance(), kTable.R);
}

// Holds `volts` for `seconds` in steps of 0.1 s (the sub-steps scale with the step).
void hold(Plant& plant, double volts, double seconds) {
  const int steps = static_cast<int>(std::lround(seconds / 0.1));
  for (int k = 0; k < steps; ++k) plant.step(volts, 0.1);
}

// The positive root of a·y² + b·y + c = 0 (a ≠ 0), in the form that does not cancel.
double positive_root(double a, double b, double c) {
  return 2.0 * (-c) / (b + std::sqrt(b * b - 4.0 * a * c));
}

TEST(PlantDeviations, ResistanceTempcoSteadyTemperature) {
  PlantDeviations d;
  d.resistance_tempco = 0.004;
  Plant plant(kTable, 20, {}, d);
  const double v = 2.0;
  // 400 s: 23 of the cold thermal time constants (a transient of 1e-10), and ρ only shortens it.
  hold(plant, v, 400.0);
  // λ·T̄ = V²/(R0·(1 + ρ·T̄))  ⇔  λρ·T̄² + λ·T̄ − V²/R0 = 0.
  const double lambda = kTable.lambda, rho = d.resistance_tempco;
  const double expected = positive_root(lambda * rho, lambda, -v * v / kTable.R);
  ASSERT_GT(std::abs(expected - v * v / (kTable.R * lambda)), 0.1 * expected);  // a real change
  EXPECT_NEAR(plant.tbar(), expected, 1e-9 * expected);
  EXPECT_NEAR(plant.resistance(), kTable.R * (1.0 + rho * expected), 1e-9);
  EXPECT_NEAR(plant.current(v), v / (kTable.R * (1.0 + rho * expected)), 1e-9);
  EXPECT_NEAR(plant.x(), -kTable.alpha2 * expected / kTable.k, 1e-9 * plant.tbar());
}

TEST(PlantDeviations, CoolingTempcoSteadyTemperature) {
  PlantDeviations d;
  d.cooling_tempco = 0.005;
  Plant plant(kTable, 20, {}, d);
  const double v = 2.0;
  hold(plant, v, 400.0);
  // λ0·(1 + γ·T̄)·T̄ = V²/R0.
  const double expected =
      positive_root(kTable.lambda * d.cooling_tempco, kTable.lambda, -v * v / kTable.R);
  EXPECT_NEAR(plant.tbar(), expected, 1e-9 * expected);
}

TEST(PlantDeviations, StiffnessSofteningStaticDisplacement) {
  PlantDeviations d;
  d.stiffness_softening = 0.003;
  Plant plant(kTable, 20, {}, d);
  const double v = 2.0;
  hold(plant, v, 400.0);
  const double tbar = v * v / (kTable.R * kTable.lambda);
  EXPECT_NEAR(plant.tbar(), tbar, 1e-9 * tbar);
  const double expected = -kTable.alpha2 * tbar / (kTable.k * (1.0 - d.stiffness_softening * tbar));
  ASSERT_GT(std::abs(expected), 1.2 * kTable.alpha2 * tbar / kTable.k);  // softer by > 20 %
  EXPECT_NEAR(plant.x(), expected, 1e-9 * std::abs(expected));
  EXPECT_NEAR(plant.xdot(), 0.0, 1e-12);
}

TEST(PlantDeviations, AllTempcosTogetherSteadyState) {
  PlantDeviations d;
  d.resistance_tempco = 0.0059;
  d.cooling_tempco = 0.004;
  d.stiffness_softening = 0.003;
  Plant plant(kTable, 20, {}, d);
  const double v = 2.5;
  hold(plant, v, 400.0);
  // λ0(1 + γT̄)·T̄·(1 + ρT̄) = V²/R0: the left side grows monotonically, so bisect.
  auto excess = [&](double tb) {
    return kTable.lambda * (1.0 + d.cooling_tempco * tb) * tb * (1.0 + d.resistance_tempco * tb) -
           v * v / kTable.R;
  };
  double lo = 0.0, hi = 200.0;
  for (int i = 0; i < 200; ++i) (excess(0.5 * (lo + hi)) > 0.0 ? hi : lo) = 0.5 * (lo + hi);
  const double tbar = 0.5 * (lo + hi);
  EXPECT_NEAR(plant.tbar(), tbar, 1e-9 * tbar);
  const double x = -kTable.alpha2 * tbar / (kTable.k * (1.0 - d.stiffness_softening * tbar));
  EXPECT_NEAR(plant.x(), x, 1e-9 * std::abs(x));
}

TEST(PlantDeviations, TemperatureSensorLagStepResponse) {
  PlantParams p = kTable;
  p.Cth = 1e12;  // T̄ holds still (λ/Cth ≈ 5e-14 /s): the sensor alone moves
  PlantDeviations d;
  d.temperature_lag_s = 0.3;
  Plant plant(p, 20, {}, d);
  plant.set_state(0.0, 0.0, 20.0);
  EXPECT_EQ(plant.sensed_tbar(), 20.0);  // at equilibrium after set_state
  plant.set_sensed_tbar(0.0);            // a sensor that has not seen the step yet
  double max_err = 0.0;
  for (int k = 1; k <= 3000; ++k) {
    plant.step(0.0, 1e-3);
    const double expected = 20.0 * (1.0 - std::exp(-k * 1e-3 / d.temperature_lag_s));
    max_err = std::max(max_err, std::abs(plant.sensed_tbar() - expected));
  }
  EXPECT_LT(max_err, 1e-10 * 20.0);
  EXPECT_NEAR(plant.sensed_tbar(), 20.0, 1e-3);  // 10 time constants
}

// A room warming at r = drift/3600 °C/s with no heating: T̄ = T − T_true obeys
// dT̄/dt = −a·T̄ − r, so T̄(t) = −(r/a)(1 − e^{−at}): the actuator lags the room. The sensor reads
// T̄ + offset + r·t through its lag τ; for that input from equilibrium its closed form is
//   s(t) = offset + r(t − τ) − r/a + (r/a)·e^{−at}/(1 − aτ) − r·a·τ²/(1 − aτ)·e^{−t/τ}.
TEST(PlantDeviations, AmbientDriftAndLagClosedForm) {
  PlantDeviations d;
  d.ambient_offset_c = 1.5;
  d.ambient_drift_c_per_h = 50.0;
  d.temperature_lag_s = 0.5;
  Plant plant(kTable, 20, {}, d);
  Plant unlagged(kTable, 20, {}, [&] {
    PlantDeviations u = d;
    u.temperature_lag_s = 0.0;
    return u;
  }());
  EXPECT_EQ(plant.sensed_tbar(), 1.5);  // at rest at the true ambient, offset from the configured
  const double r = d.ambient_drift_c_per_h / 3600.0, a = kTable.lambda / kTable.Cth;
  const double tau = d.temperature_lag_s;
  double err_tbar = 0.0, err_sensed = 0.0, err_unlagged = 0.0;
  for (int k = 1; k <= 120000; ++k) {
    plant.step(0.0, 1e-3);
    unlagged.step(0.0, 1e-3);
    if (k % 100 != 0) continue;
    const double t = k * 1e-3;
    const double tbar = -(r / a) * (1.0 - std::exp(-a * t));
    const double sensed = d.ambient_offset_c + r * (t - tau) - r / a +
                          (r / a) * std::exp(-a * t) / (1.0 - a * tau) -
                          r * a * tau * tau / (1.0 - a * tau) * std::exp(-t / tau);
    err_tbar = std::max(err_tbar, std::abs(plant.tbar() - tbar));
    err_sensed = std::max(err_sensed, std::abs(plant.sensed_tbar() - sensed));
    err_unlagged = std::max(err_unlagged, std::abs(unlagged.sensed_tbar() - (tbar + 1.5 + r * t)));
  }
  // The drift moved T̄ by r/a·(1 − e^{−7}) ≈ 0.23 °C and the lag the reading by r·τ ≈ 7e-3 °C.
  EXPECT_LT(err_tbar, 1e-11);
  EXPECT_LT(err_sensed, 1e-11);
  EXPECT_LT(err_unlagged, 1e-11);
  EXPECT_NEAR(plant.ambient_shift(), 1.5 + r * plant.time(), 1e-12);
  // x rests at 0 at the true ambient: it follows T̄ quasi-statically, −α2·T̄/k.
  EXPECT_NEAR(plant.x(), -kTable.alpha2 * plant.tbar() / kTable.k, 1e-3 * std::abs(plant.x()));
}

// V(t) = √(q·t): V² grows linearly, so with the paper's thermal model
// T̄(t) = (q/(R·Cth·a))·(t − (1 − e^{−at})/a), a = λ/Cth.
TEST(PlantDeviations, ContinuousVoltageFollowsClosedForm) {
  Plant plant;
  const double q = 0.02;  // V²/s: 3 V after 450 s
  const auto v = [q](double t) noexcept { return std::sqrt(q * std::max(0.0, t)); };
  const double a = kTable.lambda / kTable.Cth, gain = q / (kTable.R * kTable.Cth * a);
  double max_err = 0.0;
  for (int k = 0; k < 450; ++k) {
    plant.set_time(k * 1.0);
    plant.step(VoltageOfTime(v), 1.0);
    const double t = (k + 1) * 1.0;
    max_err = std::max(max_err, std::abs(plant.tbar() - gain * (t - (1.0 - std::exp(-a * t)) / a)));
  }
  EXPECT_LT(max_err, 1e-9 * plant.tbar());
}

TEST(PlantDeviations, ContinuousConstantVoltageEqualsHeld) {
  Plant held, continuous;
  const auto two_volts = [](double) noexcept { return 2.0; };
  for (int k = 0; k < 20000; ++k) {
    held.step(2.0, 1e-3);
    continuous.step(VoltageOfTime(two_volts), 1e-3);
  }
  // Exact thermal against RK4 on it: the same to rounding.
  EXPECT_NEAR(continuous.tbar(), held.tbar(), 1e-11 * held.tbar());
  EXPECT_NEAR(continuous.x(), held.x(), 1e-9 * std::abs(held.x()));
  EXPECT_NEAR(continuous.time(), held.time(), 1e-12);
}

TEST(PlantDeviations, JointIntegrationConvergesAtTheDefaultSubstep) {
  PlantDeviations d;
  d.resistance_tempco = 0.0059;
  d.stiffness_softening = 0.003;
  d.cooling_tempco = 0.005;
  d.ambient_drift_c_per_h = 2.0;
  d.temperature_lag_s = 0.3;
  Plant coarse(kTable, 20, {}, d), fine(kTable, 400, {}, d);
  double max_x = 0.0, err_x = 0.0, err_t = 0.0;
  for (int k = 0; k < 20000; ++k) {
    const double v = paper_voltage(k * 1e-3);
    coarse.step(v, 1e-3);
    fine.step(v, 1e-3);
    max_x = std::max(max_x, std::abs(fine.x()));
    err_x = std::max(err_x, std::abs(coarse.x() - fine.x()));
    err_t = std::max(err_t, std::abs(coarse.sensed_tbar() - fine.sensed_tbar()));
  }
  ASSERT_GT(max_x, 1e-4);
  EXPECT_LT(err_x, 1e-9 * max_x);
  EXPECT_LT(err_t, 1e-9);
}

TEST(PlantDeviations, TempcoFactorsNeverCrossZero) {
  PlantDeviations d;
  d.stiffness_softening = 0.02;  // k would reach zero at T̄ = 50 °C
  Plant plant(kTable, 20, {}, d);
  hold(plant, 3.0, 200.0);  // T̄ → 167 °C
  EXPECT_TRUE(std::isfinite(plant.x()));
  EXPECT_GT(plant.tbar(), 100.0);
}

}  // namespace
}  // namespace scp::drivers::sim

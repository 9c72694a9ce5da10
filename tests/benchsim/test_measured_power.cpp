// The heater's measured current (refine/heater_power.hpp) on files of scp-benchsim, a simulator
// other than the fit's (RK4 on every state, 20 sub-steps per ms): a heater whose resistance grows
// with temperature is fitted right with the resistance's extension off, because the measured
// power carries R(T̄); R0 and ρ come out of V/I with their σ. Read through the replay reader, as
// `scp-estimatord --replay` reads such a file.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "refine/fit.hpp"
#include "refine/heater_power.hpp"
#include "tests/benchsim/bench_window.hpp"
#include "tools/benchsim/bench_file.hpp"

namespace scp::tools::benchsim {
namespace {

constexpr double kRho = 0.004;  // 1/°C: issue 28's resistance cell
constexpr double kAmbient = 25.0;

// A DAC-held file of the paper's actuator and voltage, N1 noise, the heater's R tempco ρ, its
// current measured with `noise_current` (A).
BenchFile hot_heater(double seconds, double noise_current, unsigned seed) {
  BenchFile f = default_bench_file();
  f.duration_s = seconds;
  f.timing = VoltageTiming::dac_before;
  apply_noise_level("N1", f.sim);
  f.sim.deviations.resistance_tempco = kRho;
  f.sim.measure_current = true;
  f.sim.noise_current = noise_current;
  f.sim.seed = seed;
  return f;
}

refine::FitSettings settings() {
  refine::FitSettings s;  // the paper's model: every extension off, no nuisance term
  s.declared_noise = {1e-7, 1e-3};
  return s;
}

refine::Vector6 truth() {
  return test::theta_of(default_bench_file());
}

refine::Vector6 start() {
  refine::Vector6 s = truth();
  s.head<4>() *= 0.8;
  return s;
}

void print(const char* what, const refine::FitResult& r) {
  const refine::Vector6 th = truth();
  std::printf("%s: %s; θ err/σ", what, r.message);
  for (int i = 0; i < 6; ++i) std::printf(" %.2f", (r.theta[i] - th[i]) / r.sigma[i]);
  std::printf("; R0 %.6f (σ %.2g), ρ %.5f (σ %.2g); verdicts %s (%s), %s (%s)\n", r.heater.r0_ohm,
              r.heater.r0_sigma_ohm, r.heater.rho, r.heater.rho_sigma,
              refine::verdict_name(r.validation.mechanical.verdict),
              refine::test_name(r.validation.mechanical.decisive),
              refine::verdict_name(r.validation.thermal.verdict),
              refine::test_name(r.validation.thermal.decisive));
  for (int i = 0; i < refine::kValidationTests; ++i) {
    const refine::TestOutcome& t = r.validation.tests[static_cast<std::size_t>(i)];
    if (t.performed && t.failed)
      std::printf("  failed %s: p %.3g, effect %.3g\n",
                  refine::test_name(static_cast<refine::ValidationTest>(i)), t.p_value, t.effect);
  }
}

TEST(MeasuredPower, AResistanceTempcoIsFittedRightWithTheExtensionOff) {
  const BenchFile f = hot_heater(300.0, 1e-5, 5);
  const refine::FitResult r = refine::fit(test::window_of(f, true), start(), settings());
  print("with the current", r);
  ASSERT_TRUE(r.converged) << r.message;
  const refine::Vector6 th = truth();
  for (int i = 0; i < 6; ++i) {
    ASSERT_GT(r.sigma[i], 0.0) << i;
    EXPECT_LT(std::abs(r.theta[i] - th[i]), 4.0 * r.sigma[i])
        << i << ": " << r.theta[i] / th[i] - 1.0 << " relative, σ " << r.sigma[i] / th[i];
  }
  EXPECT_FALSE(r.extensions.resistance_tempco.kept);
  ASSERT_TRUE(r.heater.measured);
  ASSERT_GT(r.heater.r0_sigma_ohm, 0.0);
  ASSERT_GT(r.heater.rho_sigma, 0.0);
  EXPECT_LT(std::abs(r.heater.r0_ohm - f.sim.plant.R), 4.0 * r.heater.r0_sigma_ohm);
  EXPECT_LT(std::abs(r.heater.rho - kRho), 4.0 * r.heater.rho_sigma);
  ASSERT_TRUE(r.validated);
  EXPECT_EQ(r.validation.thermal.verdict, refine::Verdict::kAdequate);
  EXPECT_EQ(r.validation.mechanical.verdict, refine::Verdict::kAdequate);
}

// Each row's current belongs to the voltage that drove it: the command logged at the row before
// (a log of the command issued at t, VoltageInterval::after), or the row's own value of a
// continuous voltage (foh). A pairing off by one row would be a half-period lag of the heating.
TEST(MeasuredPower, TheCurrentIsPairedWithTheVoltageThatDroveIt) {
  struct Case {
    VoltageTiming timing;
    estimator::VoltageHold hold;
    refine::VoltageInterval interval;
  };
  for (const Case c :
       {Case{VoltageTiming::dac_after, estimator::VoltageHold::zoh, refine::VoltageInterval::after},
        Case{VoltageTiming::continuous, estimator::VoltageHold::foh,
             refine::VoltageInterval::before}}) {
    BenchFile f = hot_heater(300.0, 1e-5, 7);
    f.timing = c.timing;
    refine::FitSettings s = settings();
    s.voltage_hold = c.hold;
    s.voltage_interval = c.interval;
    s.voltage_shape = refine::VoltageShape::smooth;
    const refine::FitResult r = refine::fit(test::window_of(f, true), start(), s);
    print(std::string(name_of(c.timing)).substr(0, 10).c_str(), r);
    ASSERT_TRUE(r.converged) << r.message;
    const refine::Vector6 th = truth();
    for (int i = 0; i < 6; ++i)
      EXPECT_LT(std::abs(r.theta[i] - th[i]), 4.0 * r.sigma[i])
          << name_of(c.timing) << ", " << i << ": " << r.theta[i] / th[i] - 1.0 << " relative";
    EXPECT_LT(std::abs(r.heater.rho - kRho), 4.0 * r.heater.rho_sigma) << name_of(c.timing);
  }
}

// The same file read without its current: V²/R0 misses the hot heater's lower power, and the fit
// either does not converge or its validation says so (the test above can fail).
TEST(MeasuredPower, WithoutTheCurrentTheSameFileIsNotFittedRight) {
  const BenchFile f = hot_heater(60.0, 1e-4, 5);
  const refine::FitResult r = refine::fit(test::window_of(f, false), start(), settings());
  print("without the current", r);
  EXPECT_FALSE(r.heater.measured);
  EXPECT_TRUE(!r.converged ||
              (r.validated && r.validation.thermal.verdict == refine::Verdict::kStructure))
      << r.message;
}

// R0 and ρ from V/I alone, on a window of rows with a known T̄ (no fit): the regression, with the
// ambient's offset taken out of T̄ as the fit's nuisance terms say.
TEST(MeasuredPower, TheResistanceRegressionRecoversR0AndRho) {
  std::vector<refine::WindowSample> w;
  const double r0 = 2.0, offset = 1.5;
  for (int k = 0; k < 1000; ++k) {
    refine::WindowSample s;
    s.t = 1e-3 * k;
    s.tbar = offset + 0.05 * k;  // the recorded T̄: the true one plus the ambient's offset
    s.voltage = 1.0 + 0.001 * k;
    s.current = s.voltage / (r0 * (1.0 + kRho * (s.tbar - offset)));
    w.push_back(s);
  }
  refine::Nuisance n;
  n.ambient_offset.value = offset;
  const refine::HeaterResistance h =
      refine::regress_resistance(w, refine::VoltageInterval::before, n);
  EXPECT_NEAR(h.r0_ohm, r0, 1e-9);
  EXPECT_NEAR(h.rho, kRho, 1e-9);
  // Read on the recorded T̄, R0 is the resistance at the configured ambient: off by ρ·offset.
  const refine::HeaterResistance recorded =
      refine::regress_resistance(w, refine::VoltageInterval::before);
  EXPECT_NEAR(recorded.r0_ohm, r0 * (1.0 - kRho * offset), 1e-6 * r0);
}

}  // namespace
}  // namespace scp::tools::benchsim

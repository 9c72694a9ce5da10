// The validation of real fits (refine::fit, then refine::validate_fit) on 120 s windows of the
// paper's experiment made by a second simulator (tests/refine/deviation_record.hpp), one seed per
// case: clean windows come out adequate, and each deviation of a real bench that the fit does not
// model gives `structure` in its block, named, with its size estimated to first order. The rates
// over seeds and 300 s windows are bench/validation_sweep's (docs/validation.md).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "refine/validate_fit.hpp"
#include "tests/refine/deviation_record.hpp"
#include "tests/refine/record.hpp"

namespace scp::refine {
namespace {

constexpr double kSeconds = 120.0;

using test::kN1;
using test::kN3;
using Noise = test::Noise;

// The paper's model: the fit's nuisance terms held at 0, so that a deviation is one the fit does
// not model.
FitSettings paper_model() {
  FitSettings s;
  s.nuisance.x_zero.fixed = s.nuisance.ambient_offset.fixed = s.nuisance.ambient_drift.fixed = true;
  return s;
}

ValidationReport fit_and_validate(const test::Deviations& d, Noise noise, unsigned seed) {
  const auto clean =
      test::deviation_record(test::paper_actuator(), kSeconds, 1e-3, test::paper_voltage(), d);
  const auto w = test::with_noise(clean, {.x = noise.x, .tbar = noise.tbar, .seed = seed});
  Vector6 start = test::theta_of(test::paper_actuator());
  start.head<4>() *= 0.17;  // the paper law's biased estimate under noise
  const FitResult r = fit(w, start, paper_model());
  ValidationSettings s;
  s.declared_noise = Vector2(noise.x, noise.tbar);
  const ValidationReport v = validate_fit(w, r, s);
  std::printf("fit %s; x: %s (%s), fit %.3f %%, RMS/σ %.3g; T: %s (%s), fit %.3f %%, RMS/σ %.3g\n",
              r.converged ? "converged" : r.message, verdict_name(v.mechanical.verdict),
              test_name(v.mechanical.decisive), v.mechanical.fit_percent, v.mechanical.noise_ratio,
              verdict_name(v.thermal.verdict), test_name(v.thermal.decisive), v.thermal.fit_percent,
              v.thermal.noise_ratio);
  return v;
}

TEST(ValidationFits, CleanWindowsAreAdequate) {
  for (const Noise n : {kN1, kN3}) {
    const ValidationReport v = fit_and_validate({}, n, 1);
    EXPECT_EQ(v.mechanical.verdict, Verdict::kAdequate) << test_name(v.mechanical.decisive);
    EXPECT_EQ(v.thermal.verdict, Verdict::kAdequate) << test_name(v.thermal.decisive);
    EXPECT_NEAR(v.mechanical.noise_ratio, 1.0, 0.02);
    EXPECT_NEAR(v.thermal.noise_ratio, 1.0, 0.02);
  }
}

// One deviation: the test that must name it, its true size in that test's units, and how close
// the first-order estimate must come (relative; a term the fit has pulled θ̂ far to absorb is
// estimated less well than an additive one).
struct Case {
  const char* name;
  test::Deviations deviation;
  Noise noise;
  ValidationTest named;
  double size;
  double tolerance;
};

void expect_named(const Case& c) {
  SCOPED_TRACE(c.name);
  const ValidationReport v = fit_and_validate(c.deviation, c.noise, 1);
  const BlockReport& b = v.block(block_of(c.named));
  EXPECT_EQ(b.verdict, Verdict::kStructure);
  EXPECT_EQ(b.decisive, c.named) << test_name(b.decisive);
  const double effect = v.outcome(c.named).effect;
  EXPECT_NEAR(effect, c.size, c.tolerance * std::abs(c.size));
}

TEST(ValidationFits, ADisplacementZeroIsNamed) {
  expect_named({"50 µm, N3",
                {.displacement_zero = 50e-6},
                kN3,
                ValidationTest::kDisplacementZero,
                50e-6,
                0.15});
}

TEST(ValidationFits, AnAmbientOffsetIsNamed) {
  expect_named(
      {"1 °C, N3", {.ambient_offset = 1.0}, kN3, ValidationTest::kAmbientOffset, 1.0, 0.1});
}

TEST(ValidationFits, AnAmbientDriftIsNamed) {
  expect_named({"2 °C/h, N1",
                {.ambient_drift = 2.0 / 3600},
                kN1,
                ValidationTest::kAmbientDrift,
                2.0 / 3600,
                0.5});
}

TEST(ValidationFits, ALaggingThermometerIsNamed) {
  expect_named({"0.3 s, N3", {.sensor_lag = 0.3}, kN3, ValidationTest::kSensorLag, 0.3, 0.1});
}

TEST(ValidationFits, AHeaterResistanceTempcoIsNamed) {
  expect_named({"0.004/°C, N3",
                {.resistance_tempco = 0.004},
                kN3,
                ValidationTest::kResistanceTempco,
                0.004,
                0.5});
}

TEST(ValidationFits, StiffnessSofteningIsNamed) {
  expect_named({"0.3 %/°C, N3",
                {.stiffness_tempco = 0.003},
                kN3,
                ValidationTest::kStiffnessTempco,
                0.003,
                0.6});
}

TEST(ValidationFits, CoolingGrowingWithTemperatureIsNamed) {
  expect_named(
      {"0.5 %/°C, N3", {.cooling_tempco = 0.005}, kN3, ValidationTest::kCoolingTempco, 0.005, 0.5});
}

// The numerical floor (ValidationSettings::numerical_floor): a noise-free window of the project's
// plant (drivers/sim, RK4: not the fit's discretization) fitted as the paper model leaves only
// the simulators' and the arithmetic's rounding; both blocks are adequate and say why, with the
// tests' outcomes as computed. With the floor off, the same outcomes decide the verdicts.
TEST(ValidationFloor, ANoiseFreeFitIsBelowTheFloor) {
  const auto w = test::record(test::paper_actuator(), kSeconds, 1e-3, test::paper_voltage());
  Vector6 start = test::theta_of(test::paper_actuator());
  start.head<4>() *= 0.17;
  const FitResult r = fit(w, start, paper_model());
  ASSERT_TRUE(r.validated) << r.message;
  const ValidationReport on = validate_fit(w, r, ValidationSettings{});
  ValidationSettings off_settings;
  off_settings.numerical_floor = 0.0;
  const ValidationReport off = validate_fit(w, r, off_settings);
  for (ValidationBlock b : {ValidationBlock::kMechanical, ValidationBlock::kThermal}) {
    const BlockReport &fitted = r.validation.block(b), &floor = on.block(b), &plain = off.block(b);
    std::printf("%s: relative RMS %.3g; floor on: %s (%s); off: %s (%s)\n",
                b == ValidationBlock::kMechanical ? "x" : "T", 1.0 - floor.fit_percent / 100.0,
                verdict_name(floor.verdict), test_name(floor.decisive), verdict_name(plain.verdict),
                test_name(plain.decisive));
    EXPECT_TRUE(fitted.below_numerical_floor);
    EXPECT_EQ(fitted.verdict, Verdict::kAdequate);
    EXPECT_TRUE(floor.below_numerical_floor);
    EXPECT_EQ(floor.verdict, Verdict::kAdequate);
    EXPECT_EQ(floor.decisive, ValidationTest::kNone);
    EXPECT_FALSE(plain.below_numerical_floor);
    EXPECT_DOUBLE_EQ(plain.fit_percent, floor.fit_percent);
  }
  for (int i = 0; i < kValidationTests; ++i) {
    EXPECT_EQ(on.tests[i].performed, off.tests[i].performed);
    EXPECT_EQ(on.tests[i].failed, off.tests[i].failed);
    EXPECT_DOUBLE_EQ(on.tests[i].p_value, off.tests[i].p_value);
  }
  // Measured: the rounding's structure fails the tests; without the floor neither block would
  // pass a noise-free fit.
  EXPECT_NE(off.mechanical.verdict, Verdict::kAdequate);
  EXPECT_NE(off.thermal.verdict, Verdict::kAdequate);
}

// The floor hides no deviation: a noise-free window with a 50 µm displacement zero the fit holds
// at 0 leaves a residual far above it, and the zero is named.
TEST(ValidationFloor, ANoiseFreeDeviationIsStillNamed) {
  const auto w = test::deviation_record(test::paper_actuator(), kSeconds, 1e-3,
                                        test::paper_voltage(), {.displacement_zero = 50e-6});
  Vector6 start = test::theta_of(test::paper_actuator());
  start.head<4>() *= 0.17;
  const FitResult r = fit(w, start, paper_model());
  ASSERT_TRUE(r.validated) << r.message;
  std::printf("x: fit %.6f %%, %s (%s)\n", r.validation.mechanical.fit_percent,
              verdict_name(r.validation.mechanical.verdict),
              test_name(r.validation.mechanical.decisive));
  EXPECT_FALSE(r.validation.mechanical.below_numerical_floor);
  EXPECT_EQ(r.validation.mechanical.verdict, Verdict::kStructure);
  EXPECT_EQ(r.validation.mechanical.decisive, ValidationTest::kDisplacementZero);
}

}  // namespace
}  // namespace scp::refine

namespace scp::refine {
namespace {

// Every fit validates its own final pass (FitResult::validation): a clean window is adequate in
// both blocks, and a displacement zero the fit holds at 0 is named; estimated, its test is off and
// the block is adequate.
TEST(ValidationOfEveryFit, TheFinalPassIsValidated) {
  const auto run = [](const test::Deviations& d, const FitSettings& settings) {
    const auto clean =
        test::deviation_record(test::paper_actuator(), kSeconds, 1e-3, test::paper_voltage(), d);
    const auto w = test::with_noise(clean, {.x = kN1.x, .tbar = kN1.tbar, .seed = 1});
    Vector6 start = test::theta_of(test::paper_actuator());
    start.head<4>() *= 0.17;
    const FitResult r = fit(w, start, settings);
    std::printf(
        "fit %s; validated %d, x: %s (%s), T: %s (%s)\n", r.message, r.validated,
        verdict_name(r.validation.mechanical.verdict), test_name(r.validation.mechanical.decisive),
        verdict_name(r.validation.thermal.verdict), test_name(r.validation.thermal.decisive));
    return r;
  };
  FitSettings settings = paper_model();
  settings.declared_noise = Vector2(kN1.x, kN1.tbar);
  const FitResult clean = run({}, settings);
  EXPECT_TRUE(clean.validated);
  EXPECT_EQ(clean.validation.mechanical.verdict, Verdict::kAdequate);
  EXPECT_EQ(clean.validation.thermal.verdict, Verdict::kAdequate);
  const FitResult held = run({.displacement_zero = 20e-6}, settings);
  EXPECT_EQ(held.validation.mechanical.verdict, Verdict::kStructure);
  EXPECT_EQ(held.validation.mechanical.decisive, ValidationTest::kDisplacementZero);
  settings.nuisance.x_zero.fixed = false;
  const FitResult estimated = run({.displacement_zero = 20e-6}, settings);
  EXPECT_FALSE(estimated.validation.outcome(ValidationTest::kDisplacementZero).performed);
  EXPECT_EQ(estimated.validation.mechanical.verdict, Verdict::kAdequate);
}

}  // namespace
}  // namespace scp::refine

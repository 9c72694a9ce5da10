// The streaming validator (refine/validation.hpp) on synthetic residuals: a smooth model output
// shaped like the paper's experiment, measured outputs made of it plus white noise plus one known
// deviation at a time. No fit runs here (test_validation_fits.cpp fits real windows): the residual
// is exactly what each test is about, so a verdict, the test it names and the size it estimates
// can be checked against what was put in.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include "refine/parameters.hpp"
#include "refine/probability.hpp"
#include "refine/validate_fit.hpp"
#include "refine/validation.hpp"
#include "tests/refine/record.hpp"

namespace scp::refine {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kSigmaX = 1e-7, kSigmaT = 1e-3;  // N1

using test::paper_theta;

ValidationSettings n1_settings() {
  ValidationSettings s;
  s.mechanical_time_constant_s = 0.7;
  s.thermal_time_constant_s = 17.0;
  s.declared_noise = Vector2(kSigmaX, kSigmaT);
  return s;
}

// The model's outputs at t: T̄ about 40 °C moving on the paper's two time scales, x its quasi-static
// response, V² the input.
struct ModelOutputs {
  double tbar, x, u;
};
ModelOutputs model_at(double t) {
  const double v = 1.6 + 0.4 * std::sin(2 * kPi * 0.1 * t) + 0.4 * std::sin(2 * kPi * 0.006 * t);
  const double tbar =
      40.0 + 8.0 * std::sin(2 * kPi * 0.1 * t - 1.2) + 12.0 * std::sin(2 * kPi * 0.006 * t - 0.1);
  return {tbar, -paper_theta()[3] / paper_theta()[2] * tbar, v * v};
}

// What the measured outputs hold beyond the model (per sample: t, the model) and the noise.
using Deviation = std::function<Eigen::Vector2d(double t, const ModelOutputs& m, double rate)>;
Eigen::Vector2d none(double, const ModelOutputs&, double) {
  return Eigen::Vector2d::Zero();
}

struct StreamOptions {
  double seconds = 300.0;
  double dt = 1e-3;
  unsigned seed = 1;
  double x_slow = 0.0;  // a slow AR(1) component of the x noise (300-sample correlation), m
  // The fit's sensitivities as if it had estimated x's zero (∂x̂/∂zero = 1) and x's gain.
  bool zero_fitted = false;
};

ValidationReport run(const Deviation& deviation, const StreamOptions& o = {},
                     ValidationSettings settings = n1_settings()) {
  ResidualValidator v(paper_theta(), settings);
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<double> gauss(0.0, 1.0);
  const double rho = std::exp(-1.0 / 300.0);
  double slow = gauss(rng);
  double tbar_prev = model_at(0.0).tbar;
  const auto n = static_cast<int>(std::lround(o.seconds / o.dt)) + 1;
  for (int k = 0; k < n; ++k) {
    const double t = k * o.dt;
    const ModelOutputs m = model_at(t);
    const double rate = k > 0 ? (m.tbar - tbar_prev) / o.dt : 0.0;
    tbar_prev = m.tbar;
    const Eigen::Vector2d d = deviation(t, m, rate);
    slow = rho * slow + std::sqrt(1.0 - rho * rho) * gauss(rng);
    ValidationSample s;
    s.t = t;
    s.x_model = m.x;
    s.tbar_model = m.tbar;
    s.x = m.x + d[0] + kSigmaX * gauss(rng) + o.x_slow * slow;
    s.tbar = m.tbar + d[1] + kSigmaT * gauss(rng);
    s.thermal_input = m.u;
    s.mechanical_input = m.tbar;
    const double jx[2] = {1.0, m.x}, jt[2] = {0.0, 0.0};
    if (o.zero_fitted) {
      s.jacobian_x = jx;
      s.jacobian_tbar = jt;
    }
    v.add(s);
  }
  return v.finish();
}

void expect_adequate(const ValidationReport& r) {
  EXPECT_EQ(r.mechanical.verdict, Verdict::kAdequate) << test_name(r.mechanical.decisive);
  EXPECT_EQ(r.thermal.verdict, Verdict::kAdequate) << test_name(r.thermal.decisive);
}

TEST(Validation, WhiteResidualsAreAdequate) {
  for (unsigned seed = 1; seed <= 3; ++seed) {
    const ValidationReport r = run(none, {.seed = seed});
    expect_adequate(r);
    EXPECT_NEAR(r.mechanical.noise_ratio, 1.0, 0.01);
    EXPECT_NEAR(r.thermal.noise_ratio, 1.0, 0.01);
    EXPECT_EQ(r.samples, 300001u);
    // 0.7 s / 8 and 17 s / 8; lags of 2 and 1 time constants, whole blocks.
    EXPECT_NEAR(r.mechanical.block_s, 0.0875, 1e-12);
    EXPECT_NEAR(r.thermal.block_s, 2.125, 1e-12);
    EXPECT_NEAR(r.mechanical.whiteness_lags_s, 16 * 0.0875, 1e-9);
    EXPECT_NEAR(r.thermal.independence_lags_s, 8 * 2.125, 1e-9);
    for (int i = 0; i < kValidationTests; ++i) EXPECT_TRUE(r.tests[i].performed) << i;
  }
}

TEST(Validation, FitPercentIsCompareNrmse) {
  // y = model + white noise: ‖y − ŷ‖ = σ√N, ‖y − ȳ‖ = the output's spread (√N·sd).
  const ValidationReport r = run(none, {.seconds = 100.0});
  double sum = 0.0, squares = 0.0;
  const int n = 100001;
  for (int k = 0; k < n; ++k) {
    const double x = model_at(k * 1e-3).x;
    sum += x;
    squares += x * x;
  }
  const double sd = std::sqrt(squares / n - (sum / n) * (sum / n));
  EXPECT_NEAR(r.mechanical.fit_percent, 100.0 * (1.0 - kSigmaX / sd), 0.01);
}

TEST(Validation, AnOffsetOfXIsTheDisplacementZero) {
  const double zero = 5e-8;
  const ValidationReport r =
      run([&](double, const ModelOutputs&, double) { return Eigen::Vector2d(zero, 0.0); });
  EXPECT_EQ(r.mechanical.verdict, Verdict::kStructure);
  EXPECT_EQ(r.mechanical.decisive, ValidationTest::kDisplacementZero);
  EXPECT_NEAR(r.outcome(ValidationTest::kDisplacementZero).effect, zero, 0.05 * zero);
  EXPECT_EQ(r.thermal.verdict, Verdict::kAdequate);
}

TEST(Validation, ARampOfTIsTheAmbientDrift) {
  const double drift = 1e-5;  // °C/s: 3 mK over the window, against 1 mK of white noise
  const ValidationReport r =
      run([&](double t, const ModelOutputs&, double) { return Eigen::Vector2d(0.0, drift * t); });
  EXPECT_EQ(r.thermal.verdict, Verdict::kStructure);
  EXPECT_EQ(r.thermal.decisive, ValidationTest::kAmbientDrift);
  EXPECT_NEAR(r.outcome(ValidationTest::kAmbientDrift).effect, drift, 0.05 * drift);
  EXPECT_EQ(r.mechanical.verdict, Verdict::kAdequate);
}

TEST(Validation, ALaggingThermometerIsTheSensorLag) {
  const double lag = 0.01;  // s
  const ValidationReport r = run(
      [&](double, const ModelOutputs&, double rate) { return Eigen::Vector2d(0.0, -lag * rate); });
  EXPECT_EQ(r.thermal.verdict, Verdict::kStructure);
  EXPECT_EQ(r.thermal.decisive, ValidationTest::kSensorLag);
  EXPECT_NEAR(r.outcome(ValidationTest::kSensorLag).effect, lag, 0.05 * lag);
}

TEST(Validation, AWhiteResidualLargerThanDeclaredIsNoise) {
  ValidationSettings s = n1_settings();
  s.declared_noise[1] = 0.9 * kSigmaT;
  const ValidationReport r = run(none, {.seconds = 60.0}, s);
  EXPECT_EQ(r.thermal.verdict, Verdict::kNoiseColored);
  EXPECT_EQ(r.thermal.decisive, ValidationTest::kNoiseRatioT);
  EXPECT_NEAR(r.thermal.noise_ratio, 1.0 / 0.9, 0.01);
  EXPECT_EQ(r.mechanical.verdict, Verdict::kAdequate);
}

TEST(Validation, ColouredNoiseIsNoiseColoredNotStructure) {
  // Half the x noise's σ again in a drift of the sensor's mount (300-sample correlation: the
  // block means correlate at ~0.75). θ̂ would stay consistent; only σ is at risk.
  ValidationSettings s = n1_settings();
  s.declared_noise[0] = 0.0;  // the colour alone, not the larger RMS
  int structure = 0;
  for (unsigned seed = 1; seed <= 5; ++seed) {
    const ValidationReport r = run(none, {.seed = seed, .x_slow = 0.5 * kSigmaX}, s);
    EXPECT_NE(r.mechanical.verdict, Verdict::kAdequate);
    EXPECT_FALSE(r.outcome(ValidationTest::kNoiseRatioX).performed);
    structure += r.mechanical.verdict == Verdict::kStructure ? 1 : 0;
    if (r.mechanical.verdict == Verdict::kNoiseColored) {
      EXPECT_EQ(r.mechanical.decisive, ValidationTest::kWhitenessX);
    }
  }
  EXPECT_LE(structure, 1);
}

TEST(Validation, ATermTheFitEstimatesDropsOutOfItsTest) {
  ValidationSettings s = n1_settings();
  s.jacobian_columns = 2;
  const auto zero = [](double, const ModelOutputs&, double) { return Eigen::Vector2d(5e-8, 0.0); };
  const ValidationReport fitted = run(zero, {.seconds = 60.0, .zero_fitted = true}, s);
  EXPECT_FALSE(fitted.outcome(ValidationTest::kDisplacementZero).performed);
  // The noise ratio's degrees of freedom: N − 2 estimated columns in x, none in T̄.
  EXPECT_EQ(fitted.outcome(ValidationTest::kNoiseRatioX).dof1, 60001 - 2);
  EXPECT_EQ(fitted.outcome(ValidationTest::kNoiseRatioT).dof1, 60001);
  // Held fixed by the fit, the same column is not projected off: the zero is found again.
  s.fixed_columns[0] = true;
  const ValidationReport fixed = run(zero, {.seconds = 60.0, .zero_fitted = true}, s);
  EXPECT_EQ(fixed.mechanical.decisive, ValidationTest::kDisplacementZero);
  EXPECT_EQ(fixed.outcome(ValidationTest::kNoiseRatioX).dof1, 60001 - 1);
}

TEST(Validation, ASampleThatIsNotFiniteOrGoesBackIsLeftOut) {
  ResidualValidator v(paper_theta(), n1_settings());
  ValidationSample s;
  s.x_model = s.x = 1e-3;
  s.tbar_model = s.tbar = 40.0;
  v.add(s);
  s.t = 1e-3;
  s.x = std::numeric_limits<double>::quiet_NaN();
  v.add(s);  // not finite
  s.x = 1e-3;
  s.t = 0.0;
  v.add(s);  // goes back
  s.t = 2e-3;
  s.tbar = std::numeric_limits<double>::infinity();
  v.add(s);
  const ValidationReport r = v.finish();
  EXPECT_EQ(r.samples, 1u);
  EXPECT_EQ(r.skipped, 3u);
  EXPECT_EQ(r.mechanical.residual_rms, 0.0);
}

// A sensitivity that is not finite leaves the sample out too, whether the sample carries one
// column per slot of p (the fit's passes) or another number of them.
TEST(Validation, ASampleWithASensitivityNotFiniteIsLeftOut) {
  for (const int columns : {kParams, 3}) {
    ValidationSettings settings = n1_settings();
    settings.jacobian_columns = columns;
    ResidualValidator v(paper_theta(), settings);
    std::vector<double> jx(static_cast<std::size_t>(columns), 0.5), jt = jx;
    ValidationSample s;
    s.x_model = s.x = 1e-3;
    s.tbar_model = s.tbar = 40.0;
    s.jacobian_x = jx;
    s.jacobian_tbar = jt;
    v.add(s);
    for (const double bad :
         {std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity(),
          std::numeric_limits<double>::quiet_NaN()}) {
      for (std::vector<double>* j : {&jx, &jt}) {
        j->back() = bad;
        s.t += 1e-3;
        v.add(s);
        j->back() = 0.5;
      }
    }
    s.t += 1e-3;
    v.add(s);
    const ValidationReport r = v.finish();
    EXPECT_EQ(r.samples, 2u) << columns;
    EXPECT_EQ(r.skipped, 6u) << columns;
  }
}

TEST(Validation, NoSamplesIsUntested) {
  const ValidationReport r = ResidualValidator(paper_theta(), n1_settings()).finish();
  EXPECT_EQ(r.mechanical.verdict, Verdict::kUntested);
  EXPECT_EQ(r.thermal.verdict, Verdict::kUntested);
  EXPECT_EQ(r.samples, 0u);
}

TEST(Validation, AShortWindowLeavesTheThermalBlockUntested) {
  const ValidationReport r = run(none, {.seconds = 3.0});
  EXPECT_EQ(r.thermal.verdict, Verdict::kUntested);
  EXPECT_FALSE(r.outcome(ValidationTest::kWhitenessT).performed);
  EXPECT_EQ(r.mechanical.verdict, Verdict::kAdequate);
}

TEST(Validation, ALongWindowMergesBlocksAndStillNamesTheTerm) {
  ValidationSettings s = n1_settings();
  s.max_blocks = 256;
  const ValidationReport r =
      run([&](double, const ModelOutputs&, double) { return Eigen::Vector2d(5e-8, 0.0); }, {}, s);
  // 300 s in at most 256 blocks: 0.0875 s doubled four times.
  EXPECT_NEAR(r.mechanical.block_s, 16 * 0.0875, 1e-12);
  EXPECT_LE(r.mechanical.blocks, 257);
  EXPECT_EQ(r.mechanical.decisive, ValidationTest::kDisplacementZero);
  EXPECT_EQ(r.thermal.blocks, 142);  // not merged
}

TEST(Validation, LevelsAreSidakOverTheBlocksTestsAndDisabledOnesDoNotCount) {
  ValidationSettings s = n1_settings();
  s.disabled[static_cast<int>(ValidationTest::kSensorLag)] = true;
  s.declared_noise[0] = 0.0;
  const ValidationReport r = run(none, {.seconds = 60.0}, s);
  EXPECT_FALSE(r.outcome(ValidationTest::kSensorLag).performed);
  EXPECT_FALSE(r.outcome(ValidationTest::kNoiseRatioX).performed);
  EXPECT_DOUBLE_EQ(r.outcome(ValidationTest::kWhitenessX).level, sidak_level(0.01, 5));
  EXPECT_DOUBLE_EQ(r.outcome(ValidationTest::kWhitenessT).level, sidak_level(0.01, 7));
  for (int i = 0; i < kValidationTests; ++i) {
    const auto id = static_cast<ValidationTest>(i);
    EXPECT_STRNE(test_name(id), "none");
    EXPECT_EQ(block_of(id) == ValidationBlock::kMechanical,
              std::string(test_name(id)).ends_with("_x") ||
                  id == ValidationTest::kDisplacementZero ||
                  id == ValidationTest::kStiffnessTempco || id == ValidationTest::kThermalResidual)
        << test_name(id);
  }
}

TEST(Validation, ModelTimeConstantsAreThePoles) {
  const Vector6& th = paper_theta();
  for (double tbar : {0.0, 50.0}) {
    const double c = th[0] + th[1] * tbar;
    const double slow_root = (-c + std::sqrt(c * c - 4 * th[2])) / 2;  // −1.455 rad/s at 0 °C
    const ModelTimeConstants tc = model_time_constants(th, tbar);
    EXPECT_NEAR(tc.mechanical_s, -1.0 / slow_root, 1e-6 / std::abs(slow_root));
    EXPECT_DOUBLE_EQ(tc.thermal_s, 1.0 / th[4]);
  }
  const Vector6 under = test::theta_of(test::underdamped_actuator());  // complex poles
  EXPECT_NEAR(model_time_constants(under, 0.0).mechanical_s, 2.0 / under[0], 1e-12);
}

// validation_settings(): one set-up for the fit's final pass, validate_fit and a prediction.
TEST(Validation, SettingsComeFromTheWindowThetaAndTheFreeSlots) {
  const Vector6& th = paper_theta();
  std::vector<WindowSample> w(3);
  w[0].tbar = 10.0, w[1].tbar = 20.0, w[2].tbar = 30.0;
  ValidationSettings base;
  base.declared_noise = Vector2(1e-7, 1e-3);
  base.disabled[static_cast<int>(ValidationTest::kSensorLag)] = true;
  FreeMask free = free_slots({false, false, false, false, true, false});  // θ5 held
  free[kXZeroSlot] = true;                                                // the zero estimated
  const ValidationSettings v = validation_settings(w, th, free, base);
  const ModelTimeConstants tc = model_time_constants(th, 20.0);  // the mean measured T̄
  EXPECT_DOUBLE_EQ(v.mechanical_time_constant_s, tc.mechanical_s);
  EXPECT_DOUBLE_EQ(v.thermal_time_constant_s, tc.thermal_s);
  EXPECT_EQ(v.declared_noise, base.declared_noise);
  EXPECT_EQ(v.jacobian_columns, kParams);
  for (int i = 0; i < kParams; ++i) EXPECT_EQ(v.fixed_columns[i], !free[i]) << i;
  EXPECT_TRUE(v.disabled[static_cast<int>(ValidationTest::kSensorLag)]);
  EXPECT_TRUE(v.disabled[static_cast<int>(ValidationTest::kDisplacementZero)]);
  EXPECT_FALSE(v.disabled[static_cast<int>(ValidationTest::kAmbientOffset)]);
  EXPECT_FALSE(v.disabled[static_cast<int>(ValidationTest::kAmbientDrift)]);

  base.mechanical_time_constant_s = 0.5;  // given: kept
  const ValidationSettings p = validation_settings(w, th, std::nullopt, base);
  EXPECT_DOUBLE_EQ(p.mechanical_time_constant_s, 0.5);
  EXPECT_DOUBLE_EQ(p.thermal_time_constant_s, tc.thermal_s);
  EXPECT_EQ(p.jacobian_columns, 0);
  EXPECT_FALSE(p.disabled[static_cast<int>(ValidationTest::kDisplacementZero)]);
}

// A fit that estimated the sensor's ambient error reads T̄ as the measured one less that error:
// its time constants are the model's at the model's T̄, not at the thermocouple's.
TEST(Validation, SettingsTakeTheTimeConstantsAtTheModelsTbar) {
  const Vector6& th = paper_theta();
  constexpr double kOffset = -2.0, kDrift = 2.0 / 3600.0;  // a room 2 °C low, drifting 2 °C/h
  std::vector<WindowSample> model(3), measured(3);
  for (int k = 0; k < 3; ++k) {
    model[k].t = measured[k].t = 100.0 + 50.0 * k;
    model[k].tbar = 10.0 + 10.0 * k;
    measured[k].tbar = model[k].tbar + kOffset + kDrift * (model[k].t - model[0].t);
  }
  FreeMask free = free_slots({});
  free[kAmbientOffsetSlot] = free[kAmbientDriftSlot] = true;
  const ValidationSettings want = validation_settings(model, th, free);
  const ValidationSettings got =
      validation_settings(measured, th, free, {}, AmbientError{kOffset, kDrift});
  EXPECT_DOUBLE_EQ(got.mechanical_time_constant_s, want.mechanical_time_constant_s);
  EXPECT_DOUBLE_EQ(got.thermal_time_constant_s, want.thermal_time_constant_s);
  // The measured mean is 1.9 °C off the model's: a different mechanical constant.
  EXPECT_NE(validation_settings(measured, th, free).mechanical_time_constant_s,
            want.mechanical_time_constant_s);
}

}  // namespace
}  // namespace scp::refine

// PassSettings::validator (refine/residual_pass.hpp): a Jacobian pass that feeds the validator
// gives the report validate_fit() gives from its own pass, so the fit's final pass can validate
// at no extra simulation.
#include <gtest/gtest.h>

#include "refine/residual_pass.hpp"
#include "refine/validate_fit.hpp"
#include "tests/refine/deviation_record.hpp"
#include "tests/refine/record.hpp"

namespace scp::refine {
namespace {

TEST(ValidationHook, TheFinalPassFeedsTheSameReportAsValidateFit) {
  // A lagging thermometer and noise, at the true θ (no fit needed: what matters is that both
  // routes see the same residuals and sensitivities).
  const auto clean = test::deviation_record(test::paper_actuator(), 60.0, 1e-3,
                                            test::paper_voltage(), {.sensor_lag = 0.3});
  const auto w = test::with_noise(clean, {.x = 1e-6, .tbar = 0.1, .seed = 4});
  FitResult fit;
  fit.theta = test::theta_of(test::paper_actuator());
  fit.initial_state = InitialState::Zero();
  ValidationSettings s;
  s.mechanical_time_constant_s = 0.7;
  s.thermal_time_constant_s = 17.0;
  s.declared_noise = Vector2(1e-6, 0.1);
  const std::array<bool, 6> known{false, false, false, false, true, false};  // θ5 held
  const ValidationReport expected = validate_fit(w, fit, s, known);

  s.jacobian_columns = kParams;
  s.fixed_columns[4] = true;
  // The nuisance terms, which `fit` did not estimate.
  s.fixed_columns[kXZeroSlot] = s.fixed_columns[kAmbientOffsetSlot] =
      s.fixed_columns[kAmbientDriftSlot] = true;
  ResidualValidator validator(fit.theta, s);
  PassSettings ps;
  ps.weight = {1e12, 1e2};
  ps.validator = &validator;
  const ParamVector p = param_vector(fit.theta, fit.initial_state);
  ASSERT_TRUE(residual_pass(w, p, ps).finite);
  const ValidationReport got = validator.finish();

  EXPECT_EQ(got.samples, expected.samples);
  EXPECT_EQ(got.thermal.verdict, Verdict::kStructure);
  EXPECT_EQ(got.thermal.decisive, ValidationTest::kSensorLag);
  for (ValidationBlock b : {ValidationBlock::kMechanical, ValidationBlock::kThermal}) {
    EXPECT_EQ(got.block(b).verdict, expected.block(b).verdict);
    EXPECT_EQ(got.block(b).decisive, expected.block(b).decisive);
    EXPECT_DOUBLE_EQ(got.block(b).fit_percent, expected.block(b).fit_percent);
  }
  for (int i = 0; i < kValidationTests; ++i) {
    EXPECT_EQ(got.tests[i].performed, expected.tests[i].performed) << i;
    EXPECT_NEAR(got.tests[i].statistic, expected.tests[i].statistic,
                1e-9 * std::abs(expected.tests[i].statistic))
        << test_name(static_cast<ValidationTest>(i));
  }
}

}  // namespace
}  // namespace scp::refine

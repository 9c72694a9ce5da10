// ResidualValidator::finish(): the tests on the block means, their levels and the verdicts.
#include <algorithm>
#include <cmath>
#include <vector>

#include "refine/probability.hpp"
#include "refine/residual_tests.hpp"
#include "refine/validation.hpp"
#include "refine/validation_layout.hpp"

namespace scp::refine {

namespace {

using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::VectorXd;

// One block's decimated residual and what goes with it.
struct Block {
  MatrixXd means;
  VectorXd counts;
  double block_s = 1.0;
  double time_constant = 0.0;
  MatrixXd jacobian;       // block means of the fit's sensitivities, all-zero columns left out
  MatrixXd fitted_beyond;  // ResidualValidator::finish's thermal_fitted (thermal block)

  Block(const BlockMeans& store, double tau, int first_jacobian, const ValidationSettings& s)
      : means(store.means()), counts(store.counts()), block_s(store.block_s()), time_constant(tau) {
    std::vector<Index> used;
    for (int j = 0; j < s.jacobian_columns; ++j)
      if (!s.fixed_columns[static_cast<std::size_t>(j)] && means.rows() > 0 &&
          means.col(first_jacobian + j).cwiseAbs().maxCoeff() > 0.0)
        used.push_back(first_jacobian + j);
    jacobian.resize(means.rows(), static_cast<Index>(used.size()));
    for (std::size_t j = 0; j < used.size(); ++j)
      jacobian.col(static_cast<Index>(j)) = means.col(used[j]);
  }
  Index rows() const { return means.rows(); }
  VectorXd column(int field) const { return means.col(field); }
  // Lags spanning `span` time constants, at most a quarter of the blocks.
  int lags(double span) const {
    const double want = std::round(span * time_constant / block_s);
    const auto cap = static_cast<double>(rows() / 4);
    return static_cast<int>(std::clamp(want, 0.0, cap));
  }
};

TestOutcome from_regression(const NestedTestResult& r, bool has_effect) {
  TestOutcome o;
  o.performed = r.performed;
  if (!r.performed) return o;
  o.statistic = r.statistic;
  o.dof1 = r.dof1;
  o.dof2 = r.dof2;
  o.p_value = r.p_value;
  o.ar1 = r.ar1;
  o.explained = r.explained;
  if (has_effect) o.effect = r.coefficients[0];
  return o;
}

// The residual against one candidate, beyond the fit's sensitivities (and `also`, if given).
TestOutcome candidate_test(const Block& b, const VectorXd& candidate,
                           const VectorXd& also = VectorXd()) {
  MatrixXd x = b.jacobian;
  if (also.size() == b.rows()) {
    x.conservativeResize(Eigen::NoChange, x.cols() + 1);
    x.col(x.cols() - 1) = also;
  }
  return from_regression(nested_f_test(b.column(layout::kResidual), x, candidate, b.counts), true);
}

// The residual against the block's input at lags 0..`lags` blocks, beyond the fit's sensitivities.
TestOutcome independence_test(const Block& b, int lags) {
  const Index rows = b.rows() - lags;
  if (lags < 0 || rows < 4) return {};
  const VectorXd input = b.column(layout::kInput);
  MatrixXd z(rows, lags + 1);
  for (int l = 0; l <= lags; ++l) z.col(l) = input.segment(lags - l, rows);
  return from_regression(nested_f_test(b.column(layout::kResidual).tail(rows),
                                       b.jacobian.bottomRows(rows), z, b.counts.tail(rows)),
                         false);
}

// Where the fit estimated parameters beyond the samples' sensitivities, the recursive residuals
// of the block means on all the fit's columns; else the block means, scaled by √n (block means
// of unequal counts have unequal variances; the recursive residuals are weighted so).
VectorXd whiteness_series(const Block& b) {
  if (b.fitted_beyond.cols() == 0)
    return b.column(layout::kResidual).cwiseProduct(b.counts.cwiseSqrt());
  MatrixXd x(b.rows(), b.jacobian.cols() + b.fitted_beyond.cols());
  x << b.jacobian, b.fitted_beyond;
  return recursive_residuals(b.column(layout::kResidual), x, b.counts);
}

TestOutcome whiteness_test(const Block& b, int lags) {
  TestOutcome o;
  const VectorXd e = whiteness_series(b);
  const PortmanteauResult q = ljung_box(e, lags);
  if (q.lags < 1) return o;
  o.performed = true;
  o.statistic = q.statistic;
  o.dof1 = q.lags;
  o.p_value = q.p_value;
  return o;
}

// Σε²/σ² ~ χ²(N − p) one-sided: a residual larger than the declared sensor noise.
TestOutcome noise_ratio_test(double rss, std::size_t samples, Index parameters, double sigma) {
  TestOutcome o;
  const double dof = static_cast<double>(samples) - static_cast<double>(parameters);
  if (!(sigma > 0.0) || !(dof > 0.0)) return o;
  o.performed = true;
  o.statistic = rss / (sigma * sigma);
  o.dof1 = static_cast<int>(dof);
  o.p_value = chi_square_survival(o.statistic, dof);
  return o;
}

void summarize(BlockReport& r, const Block& b, int whiteness_lags, int independence_lags) {
  r.block_s = b.block_s;
  r.blocks = static_cast<int>(b.rows());
  r.whiteness_lags_s = whiteness_lags * b.block_s;
  r.independence_lags_s = independence_lags * b.block_s;
}

// Levels (Šidák over the block's performed tests), failures, and the verdict naming one test: a
// failed targeted test with the largest F (the term that explains most of what is left; all have
// one degree of freedom), else the independence test; else the noise test of smallest p. A block
// below the numerical floor is adequate whatever its tests say.
void decide(ValidationReport& report, ValidationBlock which, double family) {
  int performed = 0;
  bool on_time_scale = false;  // a test of the decimated residual ran (not only the noise ratio)
  for (int i = 0; i < kValidationTests; ++i) {
    const auto id = static_cast<ValidationTest>(i);
    if (block_of(id) != which || !report.tests[i].performed) continue;
    ++performed;
    if (id != ValidationTest::kNoiseRatioX && id != ValidationTest::kNoiseRatioT)
      on_time_scale = true;
  }
  const double level = sidak_level(family, performed);
  ValidationTest targeted = ValidationTest::kNone, noise = ValidationTest::kNone,
                 independence = ValidationTest::kNone;
  for (int i = 0; i < kValidationTests; ++i) {
    const auto id = static_cast<ValidationTest>(i);
    TestOutcome& o = report.tests[i];
    if (block_of(id) != which || !o.performed) continue;
    o.level = level;
    o.failed = o.p_value < level;
    if (!o.failed) continue;
    if (id == ValidationTest::kIndependenceX || id == ValidationTest::kIndependenceT) {
      independence = id;
    } else if (is_structure_test(id)) {
      if (targeted == ValidationTest::kNone || o.statistic > report.outcome(targeted).statistic)
        targeted = id;
    } else if (noise == ValidationTest::kNone || o.p_value < report.outcome(noise).p_value) {
      noise = id;
    }
  }
  BlockReport& r = which == ValidationBlock::kMechanical ? report.mechanical : report.thermal;
  if (!on_time_scale) {
    r.verdict = Verdict::kUntested;
  } else if (targeted != ValidationTest::kNone || independence != ValidationTest::kNone) {
    r.verdict = Verdict::kStructure;
    r.decisive = targeted != ValidationTest::kNone ? targeted : independence;
  } else if (noise != ValidationTest::kNone) {
    r.verdict = Verdict::kNoiseColored;
    r.decisive = noise;
  } else {
    r.verdict = Verdict::kAdequate;
  }
  if (r.verdict != Verdict::kUntested && r.below_numerical_floor) {
    r.verdict = Verdict::kAdequate;
    r.decisive = ValidationTest::kNone;
  }
}

}  // namespace

BlockLayout ResidualValidator::thermal_layout() const {
  return {thermal_.t0(), thermal_.block_s(), thermal_.indices()};
}

ValidationReport ResidualValidator::finish(const MatrixXd& thermal_fitted) const {
  ValidationReport report;
  report.samples = samples_;
  report.skipped = skipped_;
  const Block mech(mechanical_, settings_.mechanical_time_constant_s, layout::kMechanicalJacobian,
                   settings_);
  Block therm(thermal_, settings_.thermal_time_constant_s, layout::kThermalJacobian, settings_);
  if (thermal_fitted.rows() == therm.rows()) therm.fitted_beyond = thermal_fitted;
  // A disabled test is not run at all: the daemon's default fit estimates the displacement zero
  // and the ambient's offset and drift, whose regressions would be thrown away.
  auto run = [&](ValidationTest id, auto&& test) {
    if (!settings_.disabled[static_cast<int>(id)]) report.tests[static_cast<int>(id)] = test();
  };
  const int mech_white = mech.lags(settings_.whiteness_span);
  const int mech_ind = mech.lags(settings_.independence_span);
  run(ValidationTest::kWhitenessX, [&] { return whiteness_test(mech, mech_white); });
  run(ValidationTest::kNoiseRatioX, [&] {
    return noise_ratio_test(rss_[0], samples_, mech.jacobian.cols(), settings_.declared_noise[0]);
  });
  run(ValidationTest::kIndependenceX, [&] { return independence_test(mech, mech_ind); });
  run(ValidationTest::kDisplacementZero,
      [&] { return candidate_test(mech, VectorXd::Ones(mech.rows())); });
  run(ValidationTest::kStiffnessTempco,
      [&] { return candidate_test(mech, mech.column(layout::kStiffness)); });
  run(ValidationTest::kThermalResidual,
      [&] { return candidate_test(mech, mech.column(layout::kThermalResidual)); });

  const int therm_white = therm.lags(settings_.whiteness_span);
  const int therm_ind = therm.lags(settings_.independence_span);
  run(ValidationTest::kWhitenessT, [&] { return whiteness_test(therm, therm_white); });
  run(ValidationTest::kNoiseRatioT, [&] {
    return noise_ratio_test(rss_[1], samples_, therm.jacobian.cols(), settings_.declared_noise[1]);
  });
  run(ValidationTest::kIndependenceT, [&] { return independence_test(therm, therm_ind); });
  // Each given the other, so that a room drifting from where it was at the window's start is not
  // read as an offset (its mean), nor an offset as a drift: the offset is the level at the
  // window's first sample, the drift the slope.
  const VectorXd ones = VectorXd::Ones(therm.rows()), time = therm.column(layout::kTime);
  run(ValidationTest::kAmbientOffset, [&] { return candidate_test(therm, ones, time); });
  run(ValidationTest::kAmbientDrift, [&] { return candidate_test(therm, time, ones); });
  run(ValidationTest::kSensorLag,
      [&] { return candidate_test(therm, therm.column(layout::kLag)); });
  run(ValidationTest::kResistanceTempco,
      [&] { return candidate_test(therm, therm.column(layout::kResistance)); });
  run(ValidationTest::kCoolingTempco,
      [&] { return candidate_test(therm, therm.column(layout::kCooling)); });

  const double n = static_cast<double>(samples_);
  for (int c = 0; c < 2; ++c) {
    BlockReport& r = c == 0 ? report.mechanical : report.thermal;
    const double spread = y_squares_[c] - (n > 0.0 ? y_sum_[c] * y_sum_[c] / n : 0.0);
    r.fit_percent = spread > 0.0 ? 100.0 * (1.0 - std::sqrt(rss_[c] / spread)) : 0.0;
    r.residual_rms = n > 0.0 ? std::sqrt(rss_[c] / n) : 0.0;
    const double sigma = settings_.declared_noise[c];
    r.noise_ratio = sigma > 0.0 ? r.residual_rms / sigma : 0.0;
    r.below_numerical_floor =
        spread > 0.0 && std::sqrt(rss_[c] / spread) < settings_.numerical_floor;
  }
  summarize(report.mechanical, mech, mech_white, mech_ind);
  summarize(report.thermal, therm, therm_white, therm_ind);
  decide(report, ValidationBlock::kMechanical, settings_.family_level);
  decide(report, ValidationBlock::kThermal, settings_.family_level);
  return report;
}

}  // namespace scp::refine

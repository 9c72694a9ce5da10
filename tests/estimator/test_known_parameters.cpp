// Known parameters (EstimatorConfig::known → BlockRls::Settings::free) and the separate forgetting
// of the mechanical block (EstimatorConfig::forgetting_mechanical).
//
// Reference values are computed here independently: batch least squares with Eigen on the same
// data, the exponential decay of R without excitation, and the RK4 plant of test_plant.hpp.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <cmath>
#include <cstdio>
#include <functional>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "estimator/block_rls.hpp"
#include "estimator/config_check.hpp"
#include "estimator/estimator.hpp"
#include "tests/estimator/plant_rig.hpp"
#include "tests/estimator/synthetic_trajectory.hpp"
#include "tests/estimator/test_plant.hpp"

namespace scp::estimator {
namespace {

using Rls4 = BlockRls<4>;

// 300 s at h = 0.01 s, λP = 0.8/s. With random rows the error contracts at about 0.2/s
// (measured: 5e-5 after 50 s), so 300 s reach rounding.
constexpr int kBlockSteps = 30000;

Rls4::Vec block_truth() {
  return Rls4::Vec(2.0, -1.0, 0.5, 3.0);
}

Rls4::Settings block_settings(double theta0_known) {
  Rls4::Settings s;
  s.forgetting = 0.8;
  s.p0 = 100.0;
  s.p_max = 1e10;
  s.scale << 1.5, 0.3, 0.7, 2.0;
  s.theta0 << 0.0, 0.0, theta0_known, 0.0;
  s.free << 1.0, 1.0, 0.0, 1.0;  // θ_2 known
  return s;
}

// Known rows/columns of R decoupled: zero off the diagonal.
bool decoupled(const Rls4::Mat& r, int known) {
  for (int j = 0; j < 4; ++j) {
    if (j == known) continue;
    if (r(known, j) != 0.0 || r(j, known) != 0.0) return false;
  }
  return r(known, known) > 0.0;
}

TEST(KnownParameters, BlockWithCorrectKnownValueConvergesAndHoldsIt) {
  Rls4 rls(block_settings(0.5));
  std::mt19937_64 rng(12345);
  std::normal_distribution<double> n01;
  const auto f = ForgettingStep::make(0.8, 0.01);
  int moved = 0, coupled = 0, nonzero_sigma = 0;
  for (int k = 0; k < kBlockSteps; ++k) {
    const Rls4::Row w(n01(rng), n01(rng), n01(rng), n01(rng));
    const double y = w.dot(block_truth());
    rls.step(w, y - rls.predict(w), f);
    moved += rls.theta()(2) != 0.5;
    coupled += !decoupled(rls.info_scaled(), 2);
    nonzero_sigma += rls.sigma()(2) != 0.0;
  }
  EXPECT_EQ(moved, 0) << "the known parameter moved";
  EXPECT_EQ(coupled, 0) << "R coupled the known parameter";
  EXPECT_EQ(nonzero_sigma, 0);
  for (int i : {0, 1, 3}) {
    EXPECT_NEAR(rls.theta()(i), block_truth()(i), 1e-9 * std::abs(block_truth()(i))) << i;
    EXPECT_TRUE(std::isfinite(rls.sigma()(i))) << i;
  }
  EXPECT_LT(rls.eps2_mean(), 1e-18);
  EXPECT_LE(rls.p_max_eig(), 1e10);
}

// θ_2 known but 10 % wrong. Column 2 is a combination of columns 0 and 1, so the reduced problem
// (known term moved to the measured side) is consistent: its least-squares solution fits the data
// exactly and differs from the truth by −δ·(c, d, 0). The solution is computed by batch least
// squares on the same rows.
TEST(KnownParameters, BlockWithWrongKnownValueConvergesToReducedLeastSquares) {
  constexpr double c = 0.6, d = -0.4, known = 0.55;  // truth 0.5
  Rls4 rls(block_settings(known));
  std::mt19937_64 rng(777);
  std::normal_distribution<double> n01;
  const auto f = ForgettingStep::make(0.8, 0.01);
  constexpr int kSteps = kBlockSteps;
  Eigen::MatrixXd wf(kSteps, 3);
  Eigen::VectorXd yr(kSteps);
  int moved = 0;
  for (int k = 0; k < kSteps; ++k) {
    const double z0 = n01(rng), z1 = n01(rng), z3 = n01(rng);
    const Rls4::Row w(z0, z1, c * z0 + d * z1, z3);
    const double y = w.dot(block_truth());
    rls.step(w, y - rls.predict(w), f);
    moved += rls.theta()(2) != known;
    wf.row(k) << z0, z1, z3;
    yr(k) = y - w(2) * known;
  }
  EXPECT_EQ(moved, 0);
  const Eigen::Vector3d batch = wf.colPivHouseholderQr().solve(yr);
  const double batch_residual = (yr - wf * batch).norm() / yr.norm();
  EXPECT_LT(batch_residual, 1e-12);
  // By hand: θ_0 + c(0.5 − 0.55), θ_1 + d(0.5 − 0.55), θ_3.
  EXPECT_NEAR(batch(0), 1.97, 1e-12);
  EXPECT_NEAR(batch(1), -0.98, 1e-12);
  EXPECT_NEAR(batch(2), 3.0, 1e-12);

  const Rls4::Vec th = rls.theta();
  EXPECT_NEAR(th(0), batch(0), 1e-9);
  EXPECT_NEAR(th(1), batch(1), 1e-9);
  EXPECT_NEAR(th(3), batch(2), 1e-9);
  EXPECT_GT(std::abs(th(0) - block_truth()(0)), 0.029);
  EXPECT_GT(std::abs(th(1) - block_truth()(1)), 0.019);
  // ε = y − w θ̂ with the wrong known value in θ̂: consistent, so it goes to zero.
  EXPECT_LT(rls.eps2_mean(), 1e-18);
}

// Generic data (column 2 not in the span of the others): the reduced problem has a residual
// δ·(independent part of column 2), and with slow forgetting θ̂ settles near the batch least-squares
// solution of the reduced problem; the normal equations of that solution hold (residual ⟂ columns).
TEST(KnownParameters, BlockWithWrongKnownValueMatchesBatchLeastSquaresOnGenericData) {
  constexpr double known = 0.55;
  Rls4::Settings s = block_settings(known);
  s.forgetting = 0.01;  // window 100 s = 10⁴ samples: close to unweighted batch least squares
  Rls4 rls(s);
  std::mt19937_64 rng(4242);
  std::normal_distribution<double> n01;
  const auto f = ForgettingStep::make(s.forgetting, 0.01);
  constexpr int kSteps = 60000;
  std::vector<double> weight(kSteps);
  Eigen::MatrixXd wf(kSteps, 3);
  Eigen::VectorXd yr(kSteps);
  for (int k = 0; k < kSteps; ++k) {
    const double z0 = n01(rng), z1 = n01(rng), z2 = n01(rng), z3 = n01(rng);
    const Rls4::Row w(z0, z1, 0.6 * z0 - 0.4 * z1 + 0.5 * z2, z3);
    const double y = w.dot(block_truth());
    rls.step(w, y - rls.predict(w), f);
    ASSERT_EQ(rls.theta()(2), known);
    wf.row(k) << z0, z1, z3;
    yr(k) = y - w(2) * known;
  }
  // Forgetting-weighted batch least squares: weight e^{−λ(t_N − t_k)}.
  Eigen::VectorXd sw(kSteps);
  for (int k = 0; k < kSteps; ++k) sw(k) = std::sqrt(std::exp(-s.forgetting * 0.01 * (kSteps - k)));
  const Eigen::MatrixXd a = sw.asDiagonal() * wf;
  const Eigen::VectorXd b = sw.asDiagonal() * yr;
  const Eigen::Vector3d batch = a.colPivHouseholderQr().solve(b);
  const Eigen::Vector3d normal = a.transpose() * (b - a * batch);
  EXPECT_LT(normal.norm(), 1e-8 * b.norm());

  const Rls4::Vec th = rls.theta();
  const Eigen::Vector3d free(th(0), th(1), th(3));
  const double diff = (free - batch).cwiseAbs().maxCoeff();
  const double off_truth = std::abs(batch(0) - block_truth()(0));
  std::printf("generic data: |θ̂ − batch LS| %.3g, |batch LS − truth| (θ_0) %.3g\n", diff,
              off_truth);
  // Population value of the shift is δ·(0.6, −0.4, 0) = (−0.03, 0.02, 0): the estimate sits
  // near the batch solution, far closer than to the truth.
  EXPECT_GT(off_truth, 0.02);
  EXPECT_LT(diff, 0.1 * off_truth);
}

// Estimate in θ coordinates is ϑ·D with ϑ = θ0/D: not always exactly θ0 in floating point
// (1813/1500·1500 ≠ 1813). "Held at theta0" holds exactly: theta() returns theta0 for known
// entries.
TEST(KnownParameters, KnownValueIsExactlyTheta0ForAnyScale) {
  Rls4::Settings s = block_settings(1813.0);
  s.scale(2) = 1500.0;
  Rls4 rls(s);
  EXPECT_EQ(rls.theta()(2), 1813.0);
}

// When rounding pushes λ_min(R) below the floor, refresh_diagnostics() lifts it by rebuilding R
// from its eigenvectors, after decouple_known(): the rebuilt R carries rounding-level coupling of
// the known row, and the next step moves the known parameter (visible when theta0 = 0; measured
// 3e-19). decouple_known() therefore runs again after the lift.
TEST(KnownParameters, KnownParameterStaysPutWhenTheFloorIsLifted) {
  Rls4::Settings s;
  s.p_max = 1e12;
  s.p0 = 1.0;
  s.theta0.setZero();
  s.free << 1.0, 0.0, 1.0, 1.0;
  Rls4 rls(s);
  std::mt19937_64 rng(1);
  std::normal_distribution<double> n01;
  const auto f = ForgettingStep::make(0.8, 1e-3);
  int moved = 0, coupled = 0;
  for (int k = 0; k < 50000; ++k) {
    // Strong excitation in two directions, almost none in the third free one: ‖R‖ ~ 1e8, so
    // rounding of eps·‖R‖ exceeds the floor 1e-12 and the lift runs.
    const double a = 1e4 * n01(rng), b = 1e4 * n01(rng);
    rls.step(Rls4::Row(a, b, a + 1e-9 * b, a - b), n01(rng), f);
    moved += rls.theta()(1) != 0.0;
    coupled += !decoupled(rls.info_scaled(), 1);
  }
  EXPECT_EQ(moved, 0);
  EXPECT_EQ(coupled, 0);
}

// ---- Estimator on the paper's experiment (independent RK4 plant) ----

Vector6 true_theta() {  // Table I by hand
  Vector6 t;
  t << 124.7 / 0.1, 0.08 / 0.1, 181.3 / 0.1, 0.01 / 0.1, 0.0540 / 0.9090, 1.0 / 0.9090;
  return t;
}

EstimatorConfig scaled_config() {
  EstimatorConfig c;
  c.scale << 1e3, 1.0, 2e3, 0.1, 0.06, 1.0;
  return c;
}

EstimatorConfig known_km_config() {
  EstimatorConfig c = scaled_config();
  c.theta0(2) = 1813.0;
  c.known[2] = true;
  return c;
}

using test::Rig;

Vector6 rel_error(const Vector6& theta_hat) {
  return ((theta_hat - true_theta()).array() / true_theta().array()).abs().matrix();
}

TEST(KnownParameters, EstimatorWithKnownStiffnessOnThePaperExperiment) {
  Rig masked(known_km_config());
  int moved = 0, nonzero_sigma = 0;
  masked.run_until(150.0, test::paper_voltage, [&](const Rig& r, double) {
    moved += r.est.estimate().theta_hat(2) != 1813.0;
    nonzero_sigma += r.est.estimate().sigma(2) != 0.0;
  });
  Rig plain(scaled_config());
  plain.run_until(150.0, test::paper_voltage);

  const Vector6 em = rel_error(masked.est.estimate().theta_hat);
  const Vector6 ep = rel_error(plain.est.estimate().theta_hat);
  std::printf("relative error at 150 s, known k/m:");
  for (int i = 0; i < 6; ++i) std::printf(" %.2g", em(i));
  std::printf("\nrelative error at 150 s, no mask:  ");
  for (int i = 0; i < 6; ++i) std::printf(" %.2g", ep(i));
  std::printf("\n");

  EXPECT_EQ(moved, 0) << "θ̂3 left 1813";
  EXPECT_EQ(nonzero_sigma, 0);
  EXPECT_EQ(masked.est.estimate().theta_hat(2), 1813.0);
  EXPECT_LT(ep.maxCoeff(), 1e-4);  // the unmasked reference converged
  EXPECT_LT(em.maxCoeff(), 1e-4);  // and so did every free parameter with the mask
  // The thermal block does not see the mechanical mask: bit-identical.
  EXPECT_EQ(masked.est.estimate().theta_hat.tail<2>(), plain.est.estimate().theta_hat.tail<2>());
  const Eigen::Matrix4d r = masked.est.state().info_mech;
  for (int j : {0, 1, 3}) {
    EXPECT_EQ(r(2, j), 0.0) << j;
    EXPECT_EQ(r(j, 2), 0.0) << j;
  }
  EXPECT_TRUE(std::isfinite(masked.est.estimate().p_max_eig_mech));
}

using test::sample_at;

TEST(KnownParameters, RestoreUnmaskedCheckpointIntoMaskedEstimator) {
  Estimator plain(scaled_config());
  for (int k = 0; k < 5000; ++k) plain.update(sample_at(k));
  const State saved = plain.state();
  ASSERT_NE(saved.theta_hat(2), 1813.0);
  // The checkpoint couples θ3 with the others.
  ASSERT_NE(saved.info_mech(0, 2), 0.0);

  Estimator masked(known_km_config());
  ASSERT_TRUE(masked.restore(saved));
  const auto check = [&](const char* when) {
    const State s = masked.state();
    EXPECT_EQ(s.theta_hat(2), 1813.0) << when;
    EXPECT_EQ(masked.estimate().sigma(2), 0.0) << when;
    for (int j : {0, 1, 3}) {
      EXPECT_EQ(s.info_mech(2, j), 0.0) << when << " " << j;
      EXPECT_EQ(s.info_mech(j, 2), 0.0) << when << " " << j;
    }
    EXPECT_TRUE(s.info_mech.allFinite()) << when;
    EXPECT_EQ(Eigen::LLT<Eigen::Matrix4d>(s.info_mech).info(), Eigen::Success) << when;
    EXPECT_TRUE(std::isfinite(masked.estimate().p_max_eig_mech)) << when;
    EXPECT_GT(masked.estimate().p_max_eig_mech, 0.0) << when;
    EXPECT_TRUE(masked.estimate().sigma.allFinite()) << when;
  };
  check("after restore");
  // Free parameters come from the checkpoint; the free block of R too.
  for (int i : {0, 1, 3, 4, 5}) {
    EXPECT_DOUBLE_EQ(masked.state().theta_hat(i), saved.theta_hat(i)) << i;
  }
  for (int i : {0, 1, 3}) {
    for (int j : {0, 1, 3}) {
      EXPECT_NEAR(masked.state().info_mech(i, j), saved.info_mech(i, j),
                  1e-14 * std::abs(saved.info_mech(i, j)))
          << i << "," << j;
    }
  }
  for (int k = 5001; k < 8000; ++k) masked.update(sample_at(k));
  check("after 3 s more");
}

// ---- forgetting_mechanical ----

// Excite, then feed zeros: once the filtered regressor has died out, R − R_min decays exactly as
// e^{−λP t}, with λP = forgetting_mechanical for the mechanical block and forgetting for the
// thermal one.
TEST(KnownParameters, MechanicalBlockForgetsAtItsOwnRate) {
  EstimatorConfig c = scaled_config();
  c.forgetting = 0.8;
  c.forgetting_mechanical = 0.05;
  Estimator est(c);
  EstimatorConfig same = c;
  same.forgetting_mechanical = 0.0;
  Estimator ref(same);
  int k = 0;
  for (; k < 5000; ++k) {
    est.update(sample_at(k));
    ref.update(sample_at(k));
  }
  const auto zero = [](int kk) {
    return Measurement{.t = kk * 1e-3, .x = 0.0, .xdot = 0.0, .tbar = 0.0, .voltage = 0.0};
  };
  for (; k < 15000; ++k) {  // 10 s: W_f decays as e^{−βt} = e^{−30}
    est.update(zero(k));
    ref.update(zero(k));
  }
  const State a = est.state();
  for (; k < 17000; ++k) est.update(zero(k));  // 2 s more
  const State b = est.state();

  const double r_min = 1.0 / c.p_max;  // scaled coordinates; θ coordinates: r_min / D_i²
  for (int i = 0; i < 4; ++i) {
    const double floor = r_min / (c.scale(i) * c.scale(i));
    const double ratio = (b.info_mech(i, i) - floor) / (a.info_mech(i, i) - floor);
    EXPECT_NEAR(ratio, std::exp(-0.05 * 2.0), 1e-6) << "mechanical " << i;
  }
  for (int i = 0; i < 2; ++i) {
    const double floor = r_min / (c.scale(4 + i) * c.scale(4 + i));
    const double ratio = (b.info_thermal(i, i) - floor) / (a.info_thermal(i, i) - floor);
    EXPECT_NEAR(ratio, std::exp(-0.8 * 2.0), 1e-6) << "thermal " << i;
  }
  // The mechanical setting does not touch the thermal block.
  EXPECT_EQ(a.info_thermal, ref.state().info_thermal);
  EXPECT_EQ(a.theta_hat.tail<2>(), ref.state().theta_hat.tail<2>());
  // ... and it does change the mechanical one.
  EXPECT_NE(a.info_mech, ref.state().info_mech);
}

// converged_mech requires a window of (1 − e^{−1})/λP of the mechanical block. The window is
// (1 − e^{−λP t})/λP, so that takes t = 1/λP: 20 s at 0.05/s, 1.25 s for the thermal block.
TEST(KnownParameters, ConvergedMechWaitsForTheMechanicalWindow) {
  EstimatorConfig c = known_km_config();
  c.forgetting_mechanical = 0.05;
  c.converged_rel_sigma = 1e30;  // only the window guard can refuse
  Rig rig(c);
  bool early = false, thermal_early = false;
  rig.run_until(19.9, test::paper_voltage, [&](const Rig& r, double) {
    early = early || r.est.estimate().converged_mech;
    thermal_early = thermal_early || r.est.estimate().converged_thermal;
  });
  EXPECT_FALSE(early);
  EXPECT_TRUE(thermal_early);
  rig.run_until(20.1, test::paper_voltage);
  EXPECT_TRUE(rig.est.estimate().converged_mech);
}

TEST(KnownParameters, ValidateConfigRejectsNegativeMechanicalForgetting) {
  for (double bad : {-0.1, std::nan(""), 1e4}) {
    EstimatorConfig c;
    c.forgetting_mechanical = bad;
    try {
      validate_config(c);
      ADD_FAILURE() << "forgetting_mechanical = " << bad << " was accepted";
    } catch (const std::invalid_argument& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("forgetting_mechanical ="), std::string::npos) << what;
      EXPECT_NE(what.find("allowed"), std::string::npos) << what;
    }
    EXPECT_THROW(Estimator{c}, std::invalid_argument);
  }
  EstimatorConfig ok;
  ok.forgetting_mechanical = 0.0;
  EXPECT_NO_THROW(validate_config(ok));
  ok.forgetting_mechanical = 0.05;
  EXPECT_NO_THROW(Estimator{ok});
}

}  // namespace
}  // namespace scp::estimator

// The estimator on the paper's experiment, with an independent RK4 plant (test_plant.hpp):
// the identity a_f = W_f θ (eq. (17)), convergence, and behaviour without excitation.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <cstdio>
#include <functional>

#include "estimator/estimator.hpp"
#include "tests/estimator/plant_rig.hpp"
#include "tests/estimator/test_plant.hpp"

namespace scp::estimator {
namespace {

Vector6 true_theta() {  // Table I by hand, independent of model.cpp
  Vector6 t;
  t << 124.7 / 0.1, 0.08 / 0.1, 181.3 / 0.1, 0.01 / 0.1, 0.0540 / 0.9090, 1.0 / 0.9090;
  return t;
}

// β = 3, λP = 0.8, P(0) = 100·I, θ̂(0) = 0 and, as in eq. (25), no bound on P.
EstimatorConfig paper_config() {
  EstimatorConfig c;
  c.p_max = 1e300;
  return c;
}

EstimatorConfig scaled_config() {
  EstimatorConfig c;
  c.scale << 1e3, 1.0, 2e3, 0.1, 0.06, 1.0;  // typical magnitudes, known to a factor of a few
  return c;
}

double max_rel_error(const Vector6& theta_hat) {
  return ((theta_hat - true_theta()).array() / true_theta().array()).abs().maxCoeff();
}

using test::kPeriod;
using test::Rig;

TEST(EstimatorSim, FilteredIdentityHolds) {
  Rig rig(scaled_config());
  Vector2 max_af = Vector2::Zero(), max_err = Vector2::Zero();
  // The first seconds hold the start-up transient of the fast mechanical pole (−1245 rad/s,
  // comparable to the sample period), which no interpolation of samples resolves; the β filter
  // forgets it within a few 1/β.
  rig.run_until(3.0, test::paper_voltage);
  rig.run_until(60.0, test::paper_voltage, [&](const Rig& r, double) {
    const Vector2 af = r.est.estimate().af;
    const Vector2 err = af - r.est.filtered_regressor() * true_theta();
    max_af = max_af.cwiseMax(af.cwiseAbs());
    max_err = max_err.cwiseMax(err.cwiseAbs());
  });
  std::printf("identity a_f = W_f θ over 3..60 s: max|err|/max|a_f| mech %.3g, thermal %.3g\n",
              max_err(0) / max_af(0), max_err(1) / max_af(1));
  // Mechanical: the terms of W_f θ are ~1e5 × a_f and cancel, so 5e-5 of a_f is 5e-10 of them.
  EXPECT_LT(max_err(0), 5e-5 * max_af(0));  // measured 1.8e-5; plain FOH gives ~1.5e-4
  EXPECT_LT(max_err(1), 1e-7 * max_af(1));
}

// One 200 s run per configuration, reused by the tests below (about 1 s each).
struct Converged {
  Rig rig;
  double err80 = 0, err120 = 0, err200 = 0;
};

Converged converge(const EstimatorConfig& c, const char* name) {
  Converged out{Rig(c)};
  out.rig.run_until(80.0, test::paper_voltage);
  out.err80 = max_rel_error(out.rig.est.estimate().theta_hat);
  out.rig.run_until(120.0, test::paper_voltage);
  out.err120 = max_rel_error(out.rig.est.estimate().theta_hat);
  out.rig.run_until(200.0, test::paper_voltage);
  out.err200 = max_rel_error(out.rig.est.estimate().theta_hat);
  const Estimate& e = out.rig.est.estimate();
  std::printf("%s: max relative error 80 s %.3g, 120 s %.3g, 200 s %.3g\n", name, out.err80,
              out.err120, out.err200);
  std::printf("%s: per-parameter relative error at 200 s:", name);
  for (int i = 0; i < 6; ++i) {
    std::printf(" %.2g", (e.theta_hat(i) - true_theta()(i)) / true_theta()(i));
  }
  std::printf("\n%s: excitation mech %.3g thermal %.3g, max eig P mech %.3g thermal %.3g\n", name,
              e.excitation(0), e.excitation(1), e.p_max_eig_mech, e.p_max_eig_thermal);
  return out;
}

const Converged& paper_run() {
  static const Converged run = converge(paper_config(), "paper gains (p0=100, scale=1)");
  return run;
}
const Converged& scaled_run() {
  static const Converged run = converge(scaled_config(), "scaled config");
  return run;
}

TEST(EstimatorSim, ConvergesWithPaperGains) {
  const Converged& r = paper_run();
  EXPECT_LT(r.err120, 1e-3);
  EXPECT_LT(r.err200, 1e-4);
}

TEST(EstimatorSim, ConvergesWithScaledConfig) {
  const Converged& r = scaled_run();
  EXPECT_LT(r.err120, 1e-3);
  EXPECT_LT(r.err200, 1e-4);
  EXPECT_TRUE(r.rig.est.estimate().converged_thermal);
}

bool spd(const State& s) {
  return Eigen::LLT<Eigen::Matrix4d>(s.info_mech).info() == Eigen::Success &&
         Eigen::LLT<Eigen::Matrix2d>(s.info_thermal).info() == Eigen::Success;
}

// 600 s without excitation after convergence: P bounded, finite, SPD; θ̂ stays put. θ̂ at 200 s
// carries a ~3e-6 discretization bias (measured); the transient right after the switch still
// carries a little information and may move θ̂ within that band, so the whole 600 s are held to
// 1e-5 and the settled last 300 s to 1e-6.
void hold_without_excitation(const Converged& start, bool zero_voltage, const char* name) {
  Rig rig = start.rig;
  const double t0 = rig.k * kPeriod;
  const double v_hold = zero_voltage ? 0.0 : test::paper_voltage(t0);
  const Vector6 theta0 = rig.est.estimate().theta_hat;
  Vector6 theta_mid = theta0;
  const double p_max = rig.est.config().p_max;
  double max_change = 0.0, max_change_late = 0.0, max_p = 0.0;
  bool ok = true;
  const auto rel = [](const Vector6& a, const Vector6& b) {
    return ((a - b).array() / b.array()).abs().maxCoeff();
  };
  rig.run_until(
      t0 + 600.0, [&](double) { return v_hold; },
      [&](const Rig& r, double) {
        if (r.k % 1000 != 0) return;
        const Estimate& e = r.est.estimate();
        ok = ok && e.theta_hat.allFinite() && std::isfinite(e.p_max_eig_mech) &&
             std::isfinite(e.p_max_eig_thermal) && spd(r.est.state());
        max_p = std::max({max_p, e.p_max_eig_mech, e.p_max_eig_thermal});
        max_change = std::max(max_change, rel(e.theta_hat, theta0));
        const double since = r.k * kPeriod - t0;
        if (std::abs(since - 300.0) < 1e-6) theta_mid = e.theta_hat;
        if (since > 300.0) max_change_late = std::max(max_change_late, rel(e.theta_hat, theta_mid));
      });
  std::printf(
      "%s: max relative change of θ̂ over 600 s %.3g, over the last 300 s %.3g, "
      "max eig P %.3g (p_max %.3g)\n",
      name, max_change, max_change_late, max_p, p_max);
  EXPECT_TRUE(ok);
  // The bound holds up to rounding: the smallest eigenvalue of R (1/p_max) is resolved only to
  // about eps·‖R‖, here ~1e-12 against 1/p_max = 1e-10, so allow 5 %.
  EXPECT_LE(max_p, p_max * 1.05);
  EXPECT_LT(max_change, 1e-5);
  EXPECT_LT(max_change_late, 1e-6);
}

// Only the bounded configuration: the paper's unbounded eq. (25) winds P up without excitation
// by design (PAPER-NOTES), and with a bound on P in unscaled coordinates the mechanical block
// cannot converge (its weakest direction carries ~5e-17 of information, below any floor that
// double precision can resolve next to ‖R‖ ≈ 3e3).
TEST(EstimatorSim, NoExcitationConstantVoltage) {
  hold_without_excitation(scaled_run(), false, "scaled, V held");
}
TEST(EstimatorSim, NoExcitationZeroVoltage) {
  hold_without_excitation(scaled_run(), true, "scaled, V = 0");
}

}  // namespace
}  // namespace scp::estimator

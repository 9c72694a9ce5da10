// A displacement sensor whose zero is millimetres off the actuator's rest, with a coarse
// thermometer (N3), on scp-benchsim files (a simulator other than the fit's): the fit estimates
// the zero beside θ from its cold start. Its scale search must free the zero too: held there, the
// offset reads as a displacement from rest that decays, and the ratios bend to slow that decay
// (a 5 mm zero then ended at a fast pole, θ1 23-84x off, on every seed).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "refine/fit.hpp"
#include "tests/benchsim/bench_window.hpp"
#include "tests/benchsim/light_stiff_bench.hpp"
#include "tools/benchsim/bench_file.hpp"

namespace scp::tools::benchsim {
namespace {

constexpr double kZero = 5e-3;

// The daemon's defaults: every nuisance term estimated.
void free_every_nuisance_term(refine::FitSettings& s) {
  s.nuisance.x_zero.fixed = false;
  s.nuisance.ambient_offset.fixed = false;
  s.nuisance.ambient_drift.fixed = false;
  s.nuisance.sensor_lag.fixed = false;
}  // m: a clamp re-seated, a sensor re-mounted

TEST(SensorZero, AFiveMillimetreZeroAtN3IsEstimatedBesideTheta) {
  for (const unsigned seed : {1u}) {
    BenchFile f = default_bench_file();
    apply_noise_level("N3", f.sim);
    f.sim.x_zero = kZero;
    f.sim.seed = seed;
    refine::FitSettings s;  // the daemon's defaults: the nuisance terms estimated
    s.voltage_hold = estimator::VoltageHold::foh;
    s.voltage_shape = refine::VoltageShape::smooth;
    free_every_nuisance_term(s);
    const refine::Vector6 truth = test::theta_of(f);
    // A start off in its ratios, as a seed from a biased estimate can be (with the zero held in
    // the scale search, this start stalled at a fast pole).
    refine::Vector6 start = truth;
    start[0] *= 0.5;
    start[2] *= 2.0;
    start[3] *= 3.0;
    const refine::FitResult r = refine::fit(test::window_of(f), start, s);
    std::printf("[measured] seed %u: %s, %d iterations; x_zero %.6g (σ %.2g); θ err/σ", seed,
                r.message, r.iterations, r.nuisance.x_zero.value, r.nuisance.x_zero.sigma);
    for (int i = 0; i < 6; ++i) std::printf(" %.2f", (r.theta[i] - truth[i]) / r.sigma[i]);
    std::printf("\n");
    ASSERT_TRUE(r.converged) << "seed " << seed << ": " << r.message;
    for (int i = 0; i < 6; ++i) {
      ASSERT_GT(r.sigma[i], 0.0) << i;
      EXPECT_LT(std::abs(r.theta[i] - truth[i]), 4.0 * r.sigma[i])
          << "seed " << seed << ", θ" << i + 1 << ": " << r.theta[i] / truth[i] - 1.0;
    }
    EXPECT_LT(std::abs(r.nuisance.x_zero.value - kZero), 4.0 * r.nuisance.x_zero.sigma)
        << "seed " << seed;
  }
}

// Light-stiff (5 mm of stroke) with a zero of 1 mm, from a start whose mechanical θ is unusable
// (negative damping, as the paper law gave on such a file: its model has no zero), so that the fit
// starts from its default shape. That shape's static gain was fitted through the origin, and the
// zero started at 0: both bent by the offset, the fit ended at a fast pole (θ1 ×100, `model
// unstable`) for a zero of 0.2 mm already. Now the static line's constant starts the zero.
TEST(SensorZero, AZeroOfAFifthOfTheStrokeFromAnUnusableStart) {
  BenchFile f = test::light_stiff(300.0);
  f.sim.x_zero = 1e-3;
  f.timing = VoltageTiming::dac_before;
  refine::FitSettings s;
  free_every_nuisance_term(s);
  const refine::Vector6 truth = test::theta_of(f);
  refine::Vector6 start = truth;
  start[0] = -7.0;
  const refine::FitResult r = refine::fit(test::window_of(f), start, s);
  ASSERT_TRUE(r.converged) << r.message;
  EXPECT_LT(((r.theta - truth).array() / truth.array()).abs().maxCoeff(), 1e-6);
  EXPECT_NEAR(r.nuisance.x_zero.value, 1e-3, 1e-9);
}

// The paper's actuator with a 1 mm zero at N3 (scripts/deviations' x_zero cell, seed 16) from
// the paper law's θ on that file (usable: positive, and far off), so that the zero starts at 0
// and x0 at the first sample. Started from the static line's zero instead, the scale search
// ended at a fast pole (`model unstable`, θ1 −98 %).
TEST(SensorZero, AUsableStartKeepsTheZeroAtZero) {
  BenchFile f = default_bench_file();
  apply_noise_level("N3", f.sim);
  f.sim.x_zero = 1e-3;
  f.sim.seed = 16;
  refine::FitSettings s;
  s.voltage_hold = estimator::VoltageHold::foh;
  s.voltage_shape = refine::VoltageShape::smooth;
  free_every_nuisance_term(s);
  const refine::Vector6 truth = test::theta_of(f);
  refine::Vector6 paper_law;
  paper_law << 1.3475535616526675, -0.04963411895647625, 0.049038472435220276,
      1.925832136689639e-06, 0.059373158346218056, 1.0994142938199971;
  const refine::FitResult r = refine::fit(test::window_of(f), paper_law, s);
  ASSERT_TRUE(r.converged) << r.message;
  for (int i = 0; i < 6; ++i)
    EXPECT_LT(std::abs(r.theta[i] - truth[i]), 4.0 * r.sigma[i]) << "θ" << i + 1;
  EXPECT_LT(std::abs(r.nuisance.x_zero.value - 1e-3), 4.0 * r.nuisance.x_zero.sigma);
}

}  // namespace
}  // namespace scp::tools::benchsim

// A displacement sensor's zero of a millimetre (issue 28's largest), estimated by the refinement
// on an scp-benchsim file (a simulator other than the fit's) with N3 noise: the staged fit starts
// the zero from the static equilibrium (refine/stages.hpp, start_displacement_zero).
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "drivers/sim/plant.hpp"
#include "refine/fit.hpp"
#include "refine/parameters.hpp"
#include "refine/stages.hpp"
#include "tests/benchsim/bench_window.hpp"
#include "tools/benchsim/bench_file.hpp"

namespace scp::tools::benchsim {
namespace {

// Seed 7 of scripts/deviations' paper N3 x_zero cell.
BenchFile zero_of_a_millimetre() {
  BenchFile f = default_bench_file();
  apply_noise_level("N3", f.sim);
  f.sim.x_zero = 1e-3;
  f.sim.seed = 7;
  return f;
}

// The start itself: within a twentieth of the zero, where 0 (the start before it) was all of it.
// In the daemon, from the paper law's θ̂, the old start stalled this seed at a fast mechanical pole
// (θ1 11x off, `best: none`); the fit below converges from either, in half the passes from this.
TEST(DisplacementZero, TheStartIsTheStaticEquilibriums) {
  const BenchFile f = zero_of_a_millimetre();
  const std::vector<refine::WindowSample> w = test::window_of(f);
  const auto th = drivers::sim::theta_of(f.sim.plant);
  refine::ParamVector p = refine::ParamVector::Zero();
  for (int i = 0; i < 6; ++i) p[i] = 0.8 * th[static_cast<std::size_t>(i)];  // the ratio is right
  p[refine::kX0] = w.front().x;
  refine::FitSettings settings;
  settings.nuisance.x_zero.fixed = false;
  refine::start_displacement_zero(w, settings, p);
  EXPECT_NEAR(p[refine::kXZeroSlot], 1e-3, 5e-5);
  EXPECT_NEAR(p[refine::kX0] + p[refine::kXZeroSlot], w.front().x, 1e-15);
  settings.nuisance.x_zero.fixed = true;  // held: the start leaves it
  refine::ParamVector held = refine::ParamVector::Zero();
  refine::start_displacement_zero(w, settings, held);
  EXPECT_EQ(held[refine::kXZeroSlot], 0.0);
}

TEST(DisplacementZero, AMillimetreIsEstimatedAtN3) {
  const BenchFile f = zero_of_a_millimetre();
  const std::vector<refine::WindowSample> w = test::window_of(f);
  refine::FitSettings settings;
  settings.voltage_hold = estimator::VoltageHold::foh;
  settings.voltage_shape = refine::VoltageShape::smooth;
  // As the daemon fits a replay: every nuisance term estimated.
  settings.nuisance.x_zero.fixed = false;
  settings.nuisance.ambient_offset.fixed = false;
  settings.nuisance.ambient_drift.fixed = false;
  settings.nuisance.sensor_lag.fixed = false;
  settings.declared_noise = {1e-6, 0.1};
  const auto th = drivers::sim::theta_of(f.sim.plant);
  refine::Vector6 start;
  for (int i = 0; i < 6; ++i) start[i] = th[static_cast<std::size_t>(i)];
  start.head<4>() *= 0.8;
  const refine::FitResult r = refine::fit(w, start, settings);
  ASSERT_TRUE(r.converged) << r.message;
  EXPECT_LT(std::abs(r.nuisance.x_zero.value - 1e-3), 4.0 * r.nuisance.x_zero.sigma)
      << r.nuisance.x_zero.value;
  for (int i = 0; i < 6; ++i)
    EXPECT_LT(std::abs(r.theta[i] - th[static_cast<std::size_t>(i)]), 4.0 * r.sigma[i]) << i;
}

}  // namespace
}  // namespace scp::tools::benchsim

// A fast alarm's departure: step or late drift? The score blocks come from a simulation of the
// paper's plant under its four-sine voltage (the reference model and its sensitivity to b/m
// beside a plant whose b/m steps or starts to drift), so a 10 % step carries the second-order
// misfit a daemon run sees, which the linear shapes do not model.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <random>
#include <vector>

#include "health/departure_shape.hpp"
#include "tests/health/paper_plant.hpp"
#include "tests/health/synthetic_windows.hpp"

namespace scp::health {
namespace {

constexpr double kDt = 1e-3;         // s, the loop period
constexpr double kNoiseX = 1e-7;     // m, N1
constexpr int kBlockSamples = 1000;  // 1 s blocks

// States [x, ẋ, T̄] of eqs. (1)-(2) in θ form, and for the reference also [S, Ṡ] = ∂[x, ẋ]/∂θ1.
using State = std::array<double, 5>;

State derivative(const State& s, const Vector6& th, double v) {
  const double x = s[0], xd = s[1], tb = s[2], sx = s[3], sxd = s[4];
  return {xd, -th[0] * xd - th[1] * tb * xd - th[2] * x - th[3] * tb, -th[4] * tb + th[5] * v * v,
          sxd, -xd - th[0] * sxd - th[1] * tb * sxd - th[2] * sx};
}

void rk4(State& s, const Vector6& th, double t) {
  // The voltage is held over the step (a DAC), as the loop commands it.
  const double v = test::paper_voltage(t);
  const auto add = [](const State& a, const State& d, double h) {
    State r;
    for (std::size_t i = 0; i < a.size(); ++i) r[i] = a[i] + h * d[i];
    return r;
  };
  const State k1 = derivative(s, th, v);
  const State k2 = derivative(add(s, k1, kDt / 2), th, v);
  const State k3 = derivative(add(s, k2, kDt / 2), th, v);
  const State k4 = derivative(add(s, k3, kDt), th, v);
  for (std::size_t i = 0; i < s.size(); ++i)
    s[i] += kDt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
}

// Score blocks of θ1 against the paper's θ, for a plant whose θ follows `truth`, from t_first to
// t_last (the plant and the reference start together at rest at t = 0).
std::vector<ScoreBlock> simulated_blocks(const std::function<Vector6(double)>& truth,
                                         double t_first, double t_last, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> noise;
  const Vector6 reference = test::paper_theta();
  State plant{}, model{};
  std::vector<ScoreBlock> blocks;
  ScoreBlock open;
  for (long n = 0; n * kDt < t_last; ++n) {
    const double t = n * kDt;
    rk4(plant, truth(t), t);
    rk4(model, reference, t);
    if (t + kDt < t_first) continue;
    const double r = (plant[0] - model[0]) / kNoiseX + noise(rng);  // ε/σ
    const double j = model[3] / kNoiseX;                            // ∂(x/σ)/∂θ1
    if (open.samples == 0) open.t_begin = t + kDt;
    open.t_end = t + kDt;
    ++open.samples;
    open.score[0] += j * r;
    open.information(0, 0) += j * j;
    if (open.samples == kBlockSamples) {
      blocks.push_back(open);
      open = ScoreBlock{};
    }
  }
  return blocks;
}

constexpr double kMargin = 10.83;  // χ²₁ at 0.999, as the monitor uses

TEST(DepartureShape, ADampingStepIsAStepDespiteItsSecondOrderMisfit) {
  // b/m +10 % at 250 s, inside the block [249.18, 250.18] where the CUSUM last stood at zero (its
  // change point, as in a daemon run), the alarm 25 s later (the fast detector at N1 takes
  // 20-35 s for it).
  const double at = 250.0, block_phase = 0.18, onset = at - 1.0 + block_phase;
  for (std::uint64_t seed : {1u, 2u, 3u}) {
    const auto blocks = simulated_blocks(
        [&](double t) {
          Vector6 th = test::paper_theta();
          if (t >= at) th[0] *= 1.1;
          return th;
        },
        at - 200.0 + block_phase, at + 25.0, seed);
    const DepartureShape shape = fit_departure(blocks, 0, onset, 150.0);
    // The misfit is far above the noise (the reason for the residual scale).
    EXPECT_GT(shape.step.sse, 100.0 * shape.blocks) << seed;
    EXPECT_FALSE(shape.is_drift(kMargin)) << seed;
    EXPECT_NEAR(shape.step.onset, at, 1.0) << seed;
    EXPECT_NEAR(shape.step.jump / test::paper_theta()[0], 0.10, 0.02) << seed;
  }
}

TEST(DepartureShape, ADriftThatStartsLateIsADrift) {
  // b/m +20 %/h from 200.5 s, 200 s of it.
  const double at = 200.5;
  for (std::uint64_t seed : {1u, 2u, 3u}) {
    const auto blocks = simulated_blocks(
        [&](double t) {
          Vector6 th = test::paper_theta();
          th[0] *= 1.0 + 0.2 * std::max(0.0, t - at) / 3600.0;
          return th;
        },
        at - 150.0, at + 200.0, seed);
    const double cusum_onset = at + 100.0;  // the CUSUM's change point lags a ramp's start
    const DepartureShape shape = fit_departure(blocks, 0, cusum_onset, 250.0);
    EXPECT_TRUE(shape.is_drift(kMargin)) << seed;
    EXPECT_NEAR(shape.ramp.onset, at, 30.0) << seed;
    EXPECT_NEAR(shape.ramp.slope * 3600.0 / test::paper_theta()[0], 0.2, 0.05) << seed;
  }
}

TEST(DepartureShape, NoBlocksNoShape) {
  const DepartureShape shape = fit_departure({}, 0, 0.0, 10.0);
  EXPECT_EQ(shape.blocks, 0);
  EXPECT_FALSE(shape.is_drift(kMargin));
}

}  // namespace
}  // namespace scp::health

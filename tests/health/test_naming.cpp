// Naming a fast alarm's change (health/naming.hpp) on the residuals of a plant that is not the
// reference model's discretization: the paper's plant under its four-sine voltage, RK4 at 4 kHz
// with the step inside it, sampled at 1 kHz with N1 noise; the reference model (the paper's θ
// plus an error drawn from a refined window's covariance) and its sensitivities to θ and to its
// state at each seed, RK4 at 1 kHz, re-seeded every 30 s from the plant's state as the daemon
// re-seeds at each refit. The first definite name must be the parameter that moved: λ/Cth
// against 1/(R·Cth) (both heat T̄ alike over seconds), k/m against b/m, α1/m, α2/m.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <optional>
#include <random>
#include <vector>

#include "health/naming.hpp"
#include "tests/health/paper_plant.hpp"
#include "tests/health/synthetic_windows.hpp"

namespace scp::health {
namespace {

constexpr double kDt = 1e-3;                      // s, the loop period
constexpr int kPlantSubsteps = 4;                 // the plant's RK4 steps per period
constexpr double kNoiseX = 1e-7, kNoiseT = 1e-3;  // N1: m, °C
constexpr long kSeedSamples = 30000;              // the refit interval, 30 s
// As the monitor names at the default settings.
constexpr NamingSettings kNaming{kNameMargin, 0.02};

// The reference model's state and ∂[x, ẋ, T̄]/∂[θ1..θ6, x0, ẋ0, T̄0] (column-major 3×9).
constexpr int kSens = 9;
using ModelState = std::array<double, 3 + 3 * kSens>;

ModelState model_derivative(const ModelState& s, const Vector6& th, double v) {
  const test::PlantState p = test::plant_derivative({s[0], s[1], s[2]}, th, v);
  const double x = s[0], xd = s[1], tb = s[2];
  ModelState d{};
  d[0] = p[0];
  d[1] = p[1];
  d[2] = p[2];
  const std::array<std::array<double, 3>, 6> forcing = {{{0.0, -xd, 0.0},
                                                         {0.0, -tb * xd, 0.0},
                                                         {0.0, -x, 0.0},
                                                         {0.0, -tb, 0.0},
                                                         {0.0, 0.0, -tb},
                                                         {0.0, 0.0, v * v}}};
  for (int k = 0; k < kSens; ++k) {
    const double sx = s[3 + 3 * k], sv = s[4 + 3 * k], st = s[5 + 3 * k];
    d[3 + 3 * k] = sv;
    d[4 + 3 * k] = -th[2] * sx - (th[0] + th[1] * tb) * sv - (th[1] * xd + th[3]) * st;
    d[5 + 3 * k] = -th[4] * st;
    if (k < kParams)
      for (int r = 0; r < 3; ++r) d[3 + 3 * k + r] += forcing[static_cast<std::size_t>(k)][r];
  }
  return d;
}

struct Step {
  int parameter;
  double factor;
};

// The blocks of one run: the step at `at`, blocks until `until`.
std::vector<ScoreBlock> simulate(const Step& step, double at, double until, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal;
  const Vector6 truth = test::paper_theta();
  // The reference's error: a refined window's (θ1..θ4 0.8 %, correlated 0.95; θ5, θ6 1e-5).
  const Matrix6 lower = test::window_covariance_300s().llt().matrixL();
  Vector6 n;
  for (int i = 0; i < kParams; ++i) n[i] = normal(rng);
  const Vector6 reference = truth + lower * n;
  test::PlantState plant{};
  ModelState model{};
  BlockAccumulator blocks_of(1.0);
  std::vector<ScoreBlock> blocks;
  std::uint64_t segment = 0;
  const double first = at - 60.0;
  for (long k = 0; k * kDt < until; ++k) {
    const double t = k * kDt, v = test::paper_voltage(t);
    Vector6 th = truth;
    for (int sub = 0; sub < kPlantSubsteps; ++sub) {
      if (t + sub * kDt / kPlantSubsteps >= at)
        th[step.parameter] = truth[step.parameter] * step.factor;
      test::rk4_step(plant, kDt / kPlantSubsteps,
                     [&](const test::PlantState& s) { return test::plant_derivative(s, th, v); });
    }
    test::rk4_step(model, kDt,
                   [&](const ModelState& s) { return model_derivative(s, reference, v); });
    const double t_sample = t + kDt;
    if ((k + 1) % kSeedSamples == 0) {
      // A refit: the model starts again from the plant's state, its sensitivities from zero.
      model = ModelState{};
      for (int r = 0; r < 3; ++r) {
        model[static_cast<std::size_t>(r)] = plant[static_cast<std::size_t>(r)];
        model[static_cast<std::size_t>(3 + 3 * (kParams + r) + r)] = 1.0;
      }
      ++segment;
      continue;
    }
    if (t_sample < first) continue;
    const Vector2 r((plant[0] - model[0]) / kNoiseX + normal(rng),
                    (plant[2] - model[2]) / kNoiseT + normal(rng));
    Matrix26 j;
    Matrix2N nuisance = Matrix2N::Zero();
    for (int p = 0; p < kSens; ++p) {
      const double dx = model[static_cast<std::size_t>(3 + 3 * p)] / kNoiseX;
      const double dt = model[static_cast<std::size_t>(5 + 3 * p)] / kNoiseT;
      if (p < kParams) {
        j(0, p) = dx;
        j(1, p) = dt;
      } else {
        nuisance(0, p - kParams) = dx;
        nuisance(1, p - kParams) = dt;
      }
    }
    nuisance(0, 3) = 1.0 / kNoiseX;
    nuisance(1, 4) = 1.0 / kNoiseT;
    if (blocks_of.add(t_sample, r, j, nuisance, segment)) blocks.push_back(blocks_of.last());
  }
  return blocks;
}

struct FirstName {
  std::optional<Naming> name;
  double t = 0.0;
};

// Block by block after the block in which the step falls (the CUSUM's change point), as the
// monitor names: the first definite name.
FirstName first_definite(const std::vector<ScoreBlock>& blocks, double at) {
  double onset = 0.0;
  for (const auto& b : blocks)
    if (b.t_begin <= at) onset = b.t_begin;
  std::vector<ScoreBlock> since;
  for (const auto& b : blocks) {
    if (b.t_begin < onset) continue;
    since.push_back(b);
    const Naming name = weigh_change(since, onset + 0.5, test::paper_theta(), kNaming).name;
    if (name.definite) return {name, b.t_end};
  }
  return {};
}

void expect_named(const Step& step, const char* what) {
  const Vector6 theta = test::paper_theta();
  const double expected = (step.factor - 1.0) * theta[step.parameter];
  for (std::uint64_t seed = 1; seed <= 8; ++seed) {
    // The step at a random phase of the excitation and of the refits.
    std::mt19937_64 draw(seed * 7919);
    const double at = std::uniform_real_distribution<double>(200.0, 260.0)(draw);
    const auto blocks = simulate(step, at, at + 60.0, seed);
    const FirstName first = first_definite(blocks, at);
    ASSERT_TRUE(first.name.has_value()) << what << " seed " << seed << " never named";
    EXPECT_EQ(first.name->best.parameter, step.parameter) << what << " seed " << seed;
    EXPECT_LE(first.t - at, 30.0) << what << " seed " << seed;
    EXPECT_NEAR(first.name->best.delta / expected, 1.0, 0.5) << what << " seed " << seed;
  }
}

TEST(Naming, CoolingStepIsNotHeating) {
  expect_named({4, 0.9}, "λ/Cth −10 %");
}

TEST(Naming, HeatingStepIsNotCooling) {
  expect_named({5, 1.0 / 1.1}, "R +10 %");
}

// The mechanical block's changes are never named from the residuals (naming.hpp): over a minute
// after the step no definite name, and the set is θ1..θ4, the moved one among them. (Named from
// them, a k/m step was called a2/m or b/m, or k/m with the wrong sign.)
void expect_mechanical_set(const Step& step, const char* what) {
  for (std::uint64_t seed : {1u, 2u, 3u}) {
    std::mt19937_64 draw(seed * 7919);
    const double at = std::uniform_real_distribution<double>(200.0, 260.0)(draw);
    const auto blocks = simulate(step, at, at + 60.0, seed);
    EXPECT_FALSE(first_definite(blocks, at).name.has_value()) << what << " seed " << seed;
    double onset = 0.0;
    for (const auto& b : blocks)
      if (b.t_begin <= at) onset = b.t_begin;
    const Naming name = weigh_change(blocks, onset + 0.5, test::paper_theta(), kNaming).name;
    EXPECT_EQ(name.block, 0) << what << " seed " << seed;
    for (int i = 0; i < kParams; ++i)
      EXPECT_EQ(name.candidates[i], block_of(i) == 0) << what << " seed " << seed << " θ" << i + 1;
  }
}

TEST(Naming, StiffnessStepIsTheMechanicalSet) {
  expect_mechanical_set({2, 0.9}, "k/m −10 %");
}

TEST(Naming, DampingStepIsTheMechanicalSet) {
  expect_mechanical_set({0, 1.1}, "b/m +10 %");
}

}  // namespace
}  // namespace scp::health

// The parts the fit's stages share (refine/parameters.hpp, stop_reason.hpp, budget.hpp,
// stage.hpp, golden_section.hpp), each on inputs whose answer is known.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <iterator>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "refine/budget.hpp"
#include "refine/golden_section.hpp"
#include "refine/levenberg_marquardt.hpp"
#include "refine/parameters.hpp"
#include "refine/stage.hpp"
#include "refine/stop_reason.hpp"
#include "tests/refine/record.hpp"

namespace scp::refine {
namespace {

TEST(Parameters, TheSlotsFollowThePapersTheta) {
  // θ = [b/m, α1/m, k/m, α2/m, λ/Cth, 1/(R·Cth)] (estimator/model.hpp, eq. (7)).
  const auto params = test::paper_actuator();
  const Vector6 theta = test::theta_of(params);
  EXPECT_DOUBLE_EQ(theta[kDamping], params.b / params.m);
  EXPECT_DOUBLE_EQ(theta[kDampingSlope], params.alpha1 / params.m);
  EXPECT_DOUBLE_EQ(theta[kStiffness], params.k / params.m);
  EXPECT_DOUBLE_EQ(theta[kThermalForce], params.alpha2 / params.m);
  EXPECT_DOUBLE_EQ(theta[kCooling], params.lambda / params.Cth);
  EXPECT_DOUBLE_EQ(theta[kHeating], 1.0 / (params.R * params.Cth));
  // Every slot belongs to exactly one of θ's blocks or the initial state.
  std::set<int> slots(kMechanicalTheta.begin(), kMechanicalTheta.end());
  slots.insert(kThermalTheta.begin(), kThermalTheta.end());
  slots.insert({kX0, kXdot0, kTbar0});
  EXPECT_EQ(*slots.rbegin(), kModelSlots - 1);
  // ... or is a nuisance term of the outputs, after them ...
  slots.insert({kXZeroSlot, kAmbientOffsetSlot, kAmbientDriftSlot});
  EXPECT_EQ(*slots.rbegin(), kFirstExtensionSlot - 1);
  // ... or one of the optional slots, last: an extension's coefficient or the sensor's lag.
  for (const ExtensionSlot& e : kExtensionTable) {
    EXPECT_TRUE(is_extension(e.slot)) << e.slot;
    EXPECT_TRUE(is_optional(e.slot)) << e.slot;
    slots.insert(e.slot);
  }
  EXPECT_TRUE(is_optional(kSensorLagSlot));
  EXPECT_FALSE(is_extension(kSensorLagSlot));
  slots.insert(kSensorLagSlot);
  EXPECT_EQ(slots.size(), static_cast<std::size_t>(kParams));
  EXPECT_EQ(*slots.rbegin(), kParams - 1);
}

TEST(Parameters, AVectorSplitsBackIntoThetaAndTheInitialState) {
  Vector6 theta;
  theta << 1, 2, 3, 4, 5, 6;
  const Eigen::Vector3d initial(7, 8, 9);
  const ParamVector p = param_vector(theta, initial);
  EXPECT_EQ(theta_of(p), theta);
  EXPECT_EQ(initial_state_of(p), initial);
  EXPECT_EQ(p[kX0], 7);
  EXPECT_EQ(p[kTbar0], 9);
}

TEST(Parameters, FreeSlotsAndTheChannelsTheyActOn) {
  std::array<bool, kThetaSize> known{};
  known[kStiffness] = known[kHeating] = true;
  const FreeMask free = free_slots(known);
  // The paper's model: its slots as `known` says, the nuisance terms held.
  for (int i = 0; i < kModelSlots; ++i) EXPECT_EQ(free[i], i != kStiffness && i != kHeating) << i;
  for (int i = kModelSlots; i < kParams; ++i) EXPECT_FALSE(free[i]) << i;
  // T̄ sees θ5, θ6 and T̄0 only (the thermal block does not see x); x sees every slot.
  const std::array<std::size_t, 2> per_channel = parameters_per_channel(free);
  EXPECT_EQ(per_channel[0], 7u);
  EXPECT_EQ(per_channel[1], 2u);  // θ5 and T̄0: θ6 is known
  // T̄ sees θ5, θ6, T̄0 and the thermal extensions ρ, γ; κ acts on x only.
  for (int i = 0; i < kParams; ++i)
    EXPECT_EQ(acts_on_tbar(i), i == kCooling || i == kHeating || i == kTbar0 ||
                                   i == kResistanceTempcoSlot || i == kCoolingTempcoSlot)
        << i;
  // The nuisance terms, free unless fixed: x's zero in x's output, the ambient's in T̄'s.
  NuisanceSettings nuisance;
  nuisance.x_zero.fixed = nuisance.ambient_offset.fixed = false;
  const FreeMask with_nuisance = free_slots(known, nuisance);
  EXPECT_TRUE(with_nuisance[kXZeroSlot]);
  EXPECT_TRUE(with_nuisance[kAmbientOffsetSlot]);
  EXPECT_FALSE(with_nuisance[kAmbientDriftSlot]);
  const std::array<std::size_t, 2> counted = parameters_per_channel(with_nuisance);
  EXPECT_EQ(counted[0], 8u);  // the seven above and x's zero
  EXPECT_EQ(counted[1], 3u);  // θ5, T̄0 and the ambient offset
  // The extensions: free unless off; ρ and γ in both outputs, κ in x's.
  ExtensionSettings extensions;
  extensions.resistance_tempco = ExtensionMode::automatic;
  extensions.stiffness_softening = ExtensionMode::on;
  FreeMask extended = with_nuisance;
  free_extensions(extensions, extended);
  EXPECT_TRUE(extended[kResistanceTempcoSlot]);
  EXPECT_TRUE(extended[kStiffnessSofteningSlot]);
  EXPECT_FALSE(extended[kCoolingTempcoSlot]);
  const std::array<std::size_t, 2> with_extensions = parameters_per_channel(extended);
  EXPECT_EQ(with_extensions[0], 10u);  // and ρ, κ
  EXPECT_EQ(with_extensions[1], 4u);   // and ρ
}

TEST(StopReasons, EachHasItsOwnTextAndNoneHasNone) {
  EXPECT_STREQ(to_text(StopReason::none), "");
  std::set<std::string> texts;
  const StopReason all[] = {StopReason::window_too_short,
                            StopReason::window_not_finite,
                            StopReason::window_times_not_increasing,
                            StopReason::start_not_finite,
                            StopReason::cancelled,
                            StopReason::evaluation_budget_spent,
                            StopReason::work_budget_spent,
                            StopReason::input_delay_not_estimated,
                            StopReason::model_not_finite,
                            StopReason::stalled,
                            StopReason::model_unstable,
                            StopReason::fast_pole_unresolved,
                            StopReason::covariance_singular,
                            StopReason::input_delay_at_limit};
  for (const StopReason r : all) {
    EXPECT_GT(std::string(to_text(r)).size(), 5u);
    texts.insert(to_text(r));
  }
  EXPECT_EQ(texts.size(), std::size(all));
  // The texts clients and tests read (docs/protocol.md, tests/refine/test_robust.cpp).
  EXPECT_STREQ(to_text(StopReason::cancelled), "cancelled");
  EXPECT_NE(std::string(to_text(StopReason::evaluation_budget_spent)).find("budget"),
            std::string::npos);
}

TEST(FitTerms, TheDefaultsAreThePapersModel) {
  const FitSettings settings;
  EXPECT_EQ(settings.voltage_hold, estimator::VoltageHold::zoh);
  EXPECT_EQ(settings.voltage_interval, VoltageInterval::before);
  for (const NuisanceSetting* n : {&settings.nuisance.x_zero, &settings.nuisance.ambient_offset,
                                   &settings.nuisance.ambient_drift, &settings.nuisance.sensor_lag})
    EXPECT_TRUE(n->fixed && n->value == 0.0);
  for (const ExtensionMode m :
       {settings.extensions.resistance_tempco, settings.extensions.stiffness_softening,
        settings.extensions.cooling_tempco})
    EXPECT_EQ(m, ExtensionMode::off);
  EXPECT_LE(settings.declared_noise.maxCoeff(), 0.0);
  std::set<std::string> texts;
  for (const auto v : {VoltageInterval::before, VoltageInterval::after, VoltageInterval::estimate})
    texts.insert(to_text(v));
  for (const auto m : {ExtensionMode::off, ExtensionMode::on, ExtensionMode::automatic})
    texts.insert(to_text(m));
  for (const auto c :
       {InformationCriterion::none, InformationCriterion::bic, InformationCriterion::yic})
    texts.insert(to_text(c));
  EXPECT_EQ(texts.size(), 9U);
  EXPECT_EQ(texts.count(""), 0U);
  EXPECT_EQ(texts.count("unknown"), 0U);
  // Each name reads back as its value (the daemon's configuration parses with these tables).
  for (const auto v : {VoltageInterval::before, VoltageInterval::after, VoltageInterval::estimate})
    EXPECT_EQ(value_of(kVoltageIntervalNames, to_text(v)), v);
  for (const auto m : {ExtensionMode::off, ExtensionMode::on, ExtensionMode::automatic})
    EXPECT_EQ(value_of(kExtensionModeNames, to_text(m)), m);
  for (const auto c :
       {InformationCriterion::none, InformationCriterion::bic, InformationCriterion::yic})
    EXPECT_EQ(value_of(kInformationCriterionNames, to_text(c)), c);
}

TEST(Coordinates, MapTheFreeSlotsInOrderAndHoldTheRest) {
  ParamVector base = ParamVector::Zero();  // the optional slots' too: NaN != NaN
  base.head<9>() << 10, 11, 12, 13, 14, 15, 16, 17, 18;
  FreeMask free{};
  free[kTbar0] = free[kDampingSlope] = free[kCooling] = true;
  const Coordinates c(free, base);
  EXPECT_EQ(c.index, (std::vector<int>{kDampingSlope, kCooling, kTbar0}));
  EXPECT_EQ(c.start(), Eigen::Vector3d(11, 14, 18));
  const ParamVector p = c.to_p(Eigen::Vector3d(-1, -2, -3));
  ParamVector expected = base;
  expected[kDampingSlope] = -1;
  expected[kCooling] = -2;
  expected[kTbar0] = -3;
  EXPECT_EQ(p, expected);
  // ∂p/∂z: one 1 per column, in its slot's row.
  const Eigen::MatrixXd t = c.jacobian();
  ASSERT_EQ(t.rows(), kParams);
  ASSERT_EQ(t.cols(), 3);
  EXPECT_EQ(t.sum(), 3.0);
  for (Eigen::Index j = 0; j < 3; ++j) EXPECT_EQ(t(c.index[j], j), 1.0);
}

TEST(AcceptedModels, DampedAndStableOverTheTbarRange) {
  ParamVector p = param_vector(test::theta_of(test::paper_actuator()), Eigen::Vector3d::Zero());
  const TbarRange range{0.0, 100.0};
  EXPECT_TRUE(stable_over(p, range));
  // θ1 + θ2·T̄ negative at the range's hot end only.
  p[kDampingSlope] = -p[kDamping] / 50.0;
  EXPECT_FALSE(damped_over(p, range));
  EXPECT_TRUE(damped_over(p, {0.0, 40.0}));
  p = param_vector(test::theta_of(test::paper_actuator()), Eigen::Vector3d::Zero());
  p[kStiffness] = 0.0;
  EXPECT_FALSE(stable_over(p, range));
  p[kStiffness] = 1.0;
  p[kCooling] = -1e-3;
  EXPECT_FALSE(stable_over(p, range));
  // A pass that reached further widens the range.
  PassResult pass;
  pass.tbar_min = -5.0;
  pass.tbar_max = 120.0;
  const TbarRange w = widened(range, pass);
  EXPECT_EQ(w.lo, -5.0);
  EXPECT_EQ(w.hi, 120.0);
}

TEST(Budget, CountsPassesAndStopsWhenSpentOrCancelled) {
  const auto& w = test::cached_paper_record(2.0);
  const ParamVector p =
      param_vector(test::theta_of(test::paper_actuator()), Eigen::Vector3d::Zero());
  std::atomic<bool> cancel{false};
  FitSettings settings;
  settings.max_evaluations = 2;
  settings.cancel = &cancel;
  Budget budget(w, settings);
  EXPECT_DOUBLE_EQ(budget.mean_interval(), 1e-3);
  EXPECT_EQ(budget.stop(), StopReason::none);
  const PassResult first = budget.pass(w, p, {});
  EXPECT_TRUE(first.finite);
  EXPECT_EQ(budget.evaluations(), 1);
  EXPECT_EQ(budget.stop(), StopReason::none);
  // The input delay reaches the pass: the same θ fits the record worse with the voltage shifted.
  budget.set_input_delay(0.5e-3);
  const PassResult shifted = budget.pass(w, p, {});
  EXPECT_GT(shifted.cost, first.cost);
  EXPECT_EQ(budget.stop(), StopReason::evaluation_budget_spent);
  cancel = true;
  EXPECT_EQ(budget.stop(), StopReason::cancelled);
}

TEST(Budget, StopsAPassWhoseModelIsStifferThanTheSamplingShows) {
  const auto& w = test::cached_paper_record(2.0);
  Vector6 theta = test::theta_of(test::paper_actuator());
  theta[kDamping] *= 1e6;  // a fast pole ~1e9 rad/s: e⁻¹⁰⁰⁰⁰⁰⁰ per sample
  FitSettings settings;
  Budget budget(w, settings);
  const PassResult r = budget.pass(w, param_vector(theta, Eigen::Vector3d::Zero()), {});
  EXPECT_FALSE(r.finite);
  EXPECT_TRUE(r.too_stiff);
}

TEST(Budget, RefusesAPassThatCannotFinishWithoutSimulatingIt) {
  const auto& w = test::cached_paper_record(2.0);
  const Vector6 paper = test::theta_of(test::paper_actuator());
  FitSettings settings;
  Budget budget(w, settings);
  Vector6 theta = paper;
  theta[kDamping] *= 60.0;  // ρ(A)·Δt ≈ 75 over every T̄: beyond kMaxPolePerSample
  const PassResult refused = budget.pass(w, param_vector(theta, Eigen::Vector3d::Zero()), {});
  EXPECT_TRUE(refused.too_stiff);
  EXPECT_FALSE(refused.finite);
  EXPECT_EQ(refused.substeps, 0);
  EXPECT_EQ(budget.evaluations(), 1);
  // Stiff, but within the bound: simulated (and its pole not resolved by 1 kHz samples).
  theta = paper;
  theta[kDamping] *= 24.0;  // ρ(A)·Δt ≈ 30
  const ParamVector stiff = param_vector(theta, Eigen::Vector3d::Zero());
  const PassResult simulated = budget.pass(w, stiff, {});
  EXPECT_TRUE(simulated.finite);
  EXPECT_GT(simulated.substeps, static_cast<long>(10 * w.size()));
  EXPECT_TRUE(budget.unresolved(stiff, simulated.tbar_min, simulated.tbar_max));
  const ParamVector p = param_vector(paper, Eigen::Vector3d::Zero());
  EXPECT_FALSE(budget.unresolved(p, 0.0, 100.0));
  EXPECT_EQ(budget.stop(), StopReason::none);
  budget.end(StopReason::stalled);
  EXPECT_EQ(budget.stop(), StopReason::stalled);
}

// cost (3 − z)², too stiff to simulate beyond z = 2, and a pole the sampling cannot resolve
// beyond z = `unresolved_beyond`.
struct WallEvaluation {
  const char* stop = nullptr;
  bool finite = false;
  double cost = 0.0;
  Eigen::MatrixXd normal = Eigen::MatrixXd::Ones(1, 1);
  Eigen::VectorXd gradient = Eigen::VectorXd::Zero(1);
  bool unresolved = false;
  bool too_stiff = false;
};

LmOutcome<WallEvaluation> descend_to_the_wall(double unresolved_beyond) {
  const auto evaluate = [&](const Eigen::VectorXd& z) {
    WallEvaluation e;
    e.too_stiff = z[0] > 2.0;
    e.finite = !e.too_stiff;
    e.cost = (3.0 - z[0]) * (3.0 - z[0]);
    e.gradient[0] = 3.0 - z[0];
    e.unresolved = z[0] > unresolved_beyond;
    return e;
  };
  LmSettings lm;
  lm.observations = 1.0;
  return levenberg_marquardt<WallEvaluation>(evaluate, Eigen::VectorXd::Zero(1), lm);
}

TEST(LevenbergMarquardt, StallsWhenAStepFromAnUnresolvedModelIsTooStiff) {
  const auto stalled = descend_to_the_wall(1.0);
  EXPECT_TRUE(stalled.stalled);
  EXPECT_FALSE(stalled.converged);
  EXPECT_GT(stalled.z[0], 1.0);
  EXPECT_LE(stalled.z[0], 2.0);
  EXPECT_NE(std::string(stalled.message).find("stalled"), std::string::npos);
  // Too stiff steps from models the sampling resolves are failed steps as before.
  const auto resolved = descend_to_the_wall(10.0);
  EXPECT_FALSE(resolved.stalled);
  EXPECT_GT(resolved.iterations, stalled.iterations);
  // A run that starts beyond the resolution may come back: it does not stall.
  const auto started_there = descend_to_the_wall(-1.0);
  EXPECT_FALSE(started_there.stalled);
}

// y = a·e^{−b·t} with unit Gaussian noise, 200 samples: a least-squares problem whose cost is
// quadratic near its minimum and far from quadratic a long way off.
struct DecayEvaluation {
  const char* stop = nullptr;
  bool finite = false;
  double cost = 0.0;
  Eigen::MatrixXd normal;
  Eigen::VectorXd gradient;
  int full_passes = 0;  // how many evaluations had a Jacobian (the start's, for an accepted step)

  void adopt_cost(const DecayEvaluation& at_step) { cost = at_step.cost; }
};

struct DecayProblem {
  std::vector<double> t, y;
  int full = 0, cost_only = 0;

  DecayProblem() {
    std::mt19937 rng(11);
    std::normal_distribution<double> noise(0.0, 1.0);
    for (int i = 0; i < 200; ++i) {
      t.push_back(0.05 * i);
      y.push_back(100.0 * std::exp(-0.7 * t.back()) + noise(rng));
    }
  }
  DecayEvaluation at(const Eigen::VectorXd& z, bool jacobian) {
    ++(jacobian ? full : cost_only);
    DecayEvaluation e;
    e.normal = Eigen::MatrixXd::Zero(2, 2);
    e.gradient = Eigen::VectorXd::Zero(2);
    for (std::size_t i = 0; i < t.size(); ++i) {
      const double g = std::exp(-z[1] * t[i]), r = y[i] - z[0] * g;
      const Eigen::Vector2d j(g, -z[0] * t[i] * g);
      e.cost += r * r;
      e.normal += j * j.transpose();
      e.gradient += j * r;
    }
    e.finite = std::isfinite(e.cost);
    e.full_passes = full;
    return e;
  }
  // `tolerance`: the decrement's and the one-step rule's (0: the full iteration only).
  LmOutcome<DecayEvaluation> fit(const Eigen::Vector2d& start, double tolerance) {
    LmSettings lm;
    lm.observations = static_cast<double>(t.size());
    lm.initial_damping = 0.0;
    const bool one_step = tolerance > 0.0;
    if (one_step) lm.decrement_tolerance = tolerance;
    const auto full_pass = [this](const Eigen::VectorXd& z) { return at(z, true); };
    if (!one_step) return levenberg_marquardt<DecayEvaluation>(full_pass, start, lm);
    lm.one_step_tolerance = tolerance;
    return levenberg_marquardt<DecayEvaluation>(
        full_pass, start, lm, [this](const Eigen::VectorXd& z) { return at(z, false); });
  }
};

TEST(LevenbergMarquardt, TakesTheFirstStepOnOneCostPassBesideTheSolution) {
  DecayProblem problem;
  const auto full = problem.fit({100.0, 0.7}, 0.0);
  ASSERT_TRUE(full.converged) << full.message;
  // σ of a and b from the normal matrix at the solution (unit noise).
  const Eigen::Vector2d sigma = full.at_z.normal.inverse().diagonal().cwiseSqrt();
  // A start 0.5σ off in both, as a neighbouring window's solution is.
  problem.full = problem.cost_only = 0;
  // Both rules at 1e-3 of the cost per observation: within √1e-3 σ of the minimum.
  const auto near = problem.fit(full.z + 0.5 * sigma, 1e-3);
  EXPECT_TRUE(near.one_step);
  EXPECT_TRUE(near.converged);
  EXPECT_EQ(problem.full, 1);
  EXPECT_EQ(problem.cost_only, 1);
  for (int i = 0; i < 2; ++i) EXPECT_LT(std::abs(near.z[i] - full.z[i]), 0.03 * sigma[i]) << i;
  // The cost is the step's, the normal matrix the start's.
  EXPECT_NEAR(near.at_z.cost, full.at_z.cost, 1e-3 * full.at_z.cost / 200.0);
  EXPECT_EQ(near.at_z.full_passes, 1);

  // Far off (b at twice its value) the linear model does not hold: the run goes on as before.
  problem.full = problem.cost_only = 0;
  const auto far = problem.fit({100.0, 1.4}, 1e-3);
  EXPECT_FALSE(far.one_step);
  EXPECT_EQ(problem.cost_only, 1);
  EXPECT_GT(problem.full, 2);
  ASSERT_TRUE(far.converged) << far.message;
  for (int i = 0; i < 2; ++i) EXPECT_LT(std::abs(far.z[i] - full.z[i]), 0.03 * sigma[i]) << i;
}

TEST(GoldenSection, FindsAParabolasVertexAndCountsItsSteps) {
  int evaluations = 0, steps = 0;
  const auto cost = [&](double x) {
    ++evaluations;
    return (x - 0.3) * (x - 0.3) + 2.0;
  };
  const GoldenResult r = golden_section(
      -1.0, 2.0, 1e-6, 200, cost, [] { return false; }, steps);
  EXPECT_NEAR(r.x, 0.3, 1e-6);
  EXPECT_NEAR(r.cost, 2.0, 1e-12);
  EXPECT_EQ(evaluations, steps + 2);
  // Each step shrinks the bracket by the golden ratio: 3 → 1e-6 takes ⌈ln(3e6)/ln φ⌉ steps.
  EXPECT_EQ(steps, static_cast<int>(std::ceil(std::log(3e6) / std::log(0.5 * (1 + std::sqrt(5))))));
  int stopped_steps = 0;
  golden_section(
      -1.0, 2.0, 1e-6, 200, cost, [&] { return stopped_steps >= 5; }, stopped_steps);
  EXPECT_EQ(stopped_steps, 5);
}

}  // namespace
}  // namespace scp::refine

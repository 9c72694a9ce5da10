// Each stage of the fit (refine/stages.hpp) on its own: handed a state, it must do its one job
// and leave the rest of the state alone. Records are the project's RK4 plant (tests/refine/
// record.hpp), not the fit's own simulator.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <random>
#include <vector>

#include "refine/covariance.hpp"
#include "refine/residual_pass.hpp"
#include "refine/stages.hpp"
#include "tests/refine/record.hpp"

namespace scp::refine {
namespace {

double relative_error(double estimate, double truth) {
  return std::abs(estimate - truth) / std::abs(truth);
}

// θ1..θ4 only.
double mechanical_error(const ParamVector& p, const Vector6& truth) {
  double worst = 0.0;
  for (const int i : kMechanicalTheta) worst = std::max(worst, relative_error(p[i], truth[i]));
  return worst;
}

// A state as the fit would hold it: θ = `theta`, the initial state from the first sample.
FitState state_at(std::span<const WindowSample> w, const Vector6& theta) {
  FitState s;
  s.p = param_vector(theta, Eigen::Vector3d(w.front().x, 0.0, w.front().tbar));
  return s;
}

class Stages : public ::testing::Test {
 protected:
  const std::vector<WindowSample>& window_ = test::cached_paper_record(60.0);
  const Vector6 truth_ = test::theta_of(test::paper_actuator());
};

TEST(CheckWindow, NamesWhatIsWrong) {
  const auto& good = test::cached_paper_record(60.0);
  std::vector<WindowSample> w(good.begin(), good.begin() + 10);
  EXPECT_EQ(check_window(w), StopReason::none);
  EXPECT_EQ(check_window(std::span(w).first(2)), StopReason::window_too_short);
  w[4].tbar = std::numeric_limits<double>::infinity();
  EXPECT_EQ(check_window(w), StopReason::window_not_finite);
  w[4].tbar = 0.0;
  w[6].t = w[5].t;
  EXPECT_EQ(check_window(w), StopReason::window_times_not_increasing);
}

TEST_F(Stages, StartPointKeepsAUsableStartAndFillsTheRestFromTheData) {
  // A usable start is kept as it is, the state from the first sample at rest.
  const Vector6 start = truth_ * 1.3;
  ParamVector p = start_point(window_, start, {});
  EXPECT_EQ(theta_of(p), start);
  EXPECT_EQ(initial_state_of(p), Eigen::Vector3d(window_.front().x, 0.0, window_.front().tbar));
  // From zero: θ5, θ6 from the data's equation error (within a few % noise-free), and a
  // mechanical shape that is damped, stiff and has the data's static gain sign.
  p = start_point(window_, Vector6::Zero(), {});
  EXPECT_LT(relative_error(p[kCooling], truth_[kCooling]), 0.05);
  EXPECT_LT(relative_error(p[kHeating], truth_[kHeating]), 0.05);
  EXPECT_GT(p[kDamping], 0.0);
  EXPECT_GT(p[kStiffness], 0.0);
  EXPECT_GT(p[kThermalForce] / p[kStiffness] * truth_[kStiffness] / truth_[kThermalForce], 0.0);
  // Known parameters stay what the caller gave, usable or not.
  std::array<bool, kThetaSize> known{};
  known[kHeating] = known[kStiffness] = true;
  p = start_point(window_, Vector6::Zero(), known);
  EXPECT_EQ(p[kHeating], 0.0);
  EXPECT_EQ(p[kStiffness], 0.0);
  EXPECT_GT(p[kCooling], 0.0);
}

TEST_F(Stages, ThermalFitsThetaFiveSixAndTbarZeroOnTbarAlone) {
  const FitSettings settings;
  FitContext ctx(window_, settings);
  Vector6 start = truth_;
  start[kCooling] *= 1.3;
  start[kHeating] *= 0.7;
  start.head<kMechanicalSize>() *= 0.5;  // wrong, and the thermal stage must not care
  FitState state = state_at(window_, start);
  ASSERT_EQ(fit_thermal(ctx, state), StopReason::none);
  std::printf("thermal stage: theta5 %.3g, theta6 %.3g off after %d iterations\n",
              relative_error(state.p[kCooling], truth_[kCooling]),
              relative_error(state.p[kHeating], truth_[kHeating]), state.iterations);
  EXPECT_LT(relative_error(state.p[kCooling], truth_[kCooling]), 1e-8);
  EXPECT_LT(relative_error(state.p[kHeating], truth_[kHeating]), 1e-8);
  EXPECT_EQ(state.p.head<kMechanicalSize>(), start.head<kMechanicalSize>());
  EXPECT_EQ(state.p[kX0], window_.front().x);
  EXPECT_GT(state.iterations, 0);
  // T̄'s noise variance at its floor (noise-free), and the model's T̄ range over the window.
  EXPECT_LT(state.noise.tbar, 1e-18);
  double lo = window_.front().tbar, hi = lo;
  for (const WindowSample& s : window_) lo = std::min(lo, s.tbar), hi = std::max(hi, s.tbar);
  EXPECT_NEAR(state.range.lo, lo, 1e-6 * hi);
  EXPECT_NEAR(state.range.hi, hi, 1e-6 * hi);
}

TEST_F(Stages, ABudgetSpentInAStageEndsTheFitWithItsReason) {
  FitSettings settings;
  settings.max_evaluations = 2;
  FitContext ctx(window_, settings);
  Vector6 start = truth_;
  start[kCooling] *= 1.3;
  FitState state = state_at(window_, start);
  EXPECT_EQ(fit_thermal(ctx, state), StopReason::evaluation_budget_spent);
  std::atomic<bool> cancel{true};
  settings.cancel = &cancel;
  FitContext cancelled(window_, settings);
  state = state_at(window_, start);
  EXPECT_EQ(fit_mechanical(cancelled, state), StopReason::cancelled);
  EXPECT_EQ(theta_of(state.p), start);
}

// A DAC that switches at the samples records its switches there: no negative delay is possible;
// a link's landings inside the interval allow one back to the earliest of them.
TEST(InputDelay, TheEarliestSwitchBoundsANegativeDelay) {
  const auto& dac = test::cached_paper_record(2.0);
  EXPECT_LT(earliest_switch_delay(dac, 1e-3), 1e-12);  // the record's stamps' rounding
  const auto link = test::link_record(test::paper_actuator(), 2.0);
  double earliest = 1.0;
  for (std::size_t k = 1; k < link.size(); ++k)
    earliest = std::min(earliest, link[k].voltage_since - link[k - 1].t);
  EXPECT_NEAR(earliest_switch_delay(link, 1.0), earliest, 1e-15);
  EXPECT_EQ(earliest_switch_delay(link, 1e-4), 1e-4);
}

TEST(InputDelay, TheStageFindsALatencyFromTbarAndAppliesIt) {
  const auto params = test::paper_actuator();
  const Vector6 truth = test::theta_of(params);
  constexpr double kLatency = 150e-6;
  const auto w = test::late_link_record(params, 60.0, kLatency);
  FitSettings settings;
  FitContext without(w, settings);
  FitState state = state_at(w, truth);
  EXPECT_EQ(fit_input_delay(without, state), StopReason::none);  // not asked for: nothing done
  EXPECT_FALSE(state.delay.ok);
  EXPECT_EQ(without.budget.evaluations(), 0);

  settings.max_input_delay_s = 2e-3;
  FitContext ctx(w, settings);
  ASSERT_EQ(fit_thermal(ctx, state), StopReason::none);
  ASSERT_EQ(fit_input_delay(ctx, state), StopReason::none);
  std::printf("delay stage: %.4f us (sigma %.4f us, x%.2f), theta6 %.3g off\n",
              state.delay.delay * 1e6, state.delay.sigma * 1e6, state.delay.sigma_inflation,
              relative_error(state.p[kHeating], truth[kHeating]));
  ASSERT_TRUE(state.delay.ok);
  EXPECT_NEAR(state.delay.delay, kLatency, 0.05e-6);
  EXPECT_GT(state.delay.sigma, 0.0);
  EXPECT_FALSE(state.delay.at_limit);
  // The thermal fit refitted at d̂, and every later pass of the fit's budget switches that late.
  EXPECT_LT(relative_error(state.p[kHeating], truth[kHeating]), 1e-6);
  const PassResult later = ctx.budget.pass(w, state.p, thermal_pass_settings());
  Budget unshifted(w, settings);
  const PassResult recorded = unshifted.pass(w, state.p, thermal_pass_settings());
  EXPECT_LT(later.cost, 1e-3 * recorded.cost);
}

TEST(InputDelay, NoHeatingNoDelay) {
  const auto& good = test::cached_paper_record(2.0);
  std::vector<WindowSample> w(good.begin(), good.begin() + 1000);
  for (auto& s : w) s.voltage = 0.0, s.x = 0.0, s.tbar = 0.0;
  FitSettings settings;
  settings.max_input_delay_s = 1e-3;
  FitContext ctx(w, settings);
  FitState state = state_at(w, test::theta_of(test::paper_actuator()));
  EXPECT_EQ(fit_input_delay(ctx, state), StopReason::input_delay_not_estimated);
}

// The paper law's biased start under noise: θ1..θ4 at a fraction of the truth. The search must
// bring the common scale most of the way; the mechanical stage does the rest.
TEST_F(Stages, TheScaleSearchFindsTheCommonScaleOfThetaOneToFour) {
  const FitSettings settings;
  FitContext ctx(window_, settings);
  Vector6 start = truth_;
  start.head<kMechanicalSize>() *= 0.17;
  FitState state = state_at(window_, start);
  state.range = {0.0, 100.0};
  ASSERT_EQ(search_scale(ctx, state), StopReason::none);
  std::printf("scale search: theta1..4 %.3g off (from %.3g) after %d evaluations\n",
              mechanical_error(state.p, truth_), 1.0 - 0.17, ctx.budget.evaluations());
  EXPECT_LT(mechanical_error(state.p, truth_), 0.25);
  EXPECT_EQ(state.p.segment<2>(kCooling), start.segment<2>(kCooling));
  ASSERT_EQ(fit_mechanical(ctx, state), StopReason::none);
  EXPECT_LT(mechanical_error(state.p, truth_), 1e-6);

  // With a mechanical parameter known there is no common scale: nothing done.
  FitSettings with_known;
  with_known.known[kStiffness] = true;
  FitContext known_ctx(window_, with_known);
  FitState untouched = state_at(window_, start);
  EXPECT_EQ(search_scale(known_ctx, untouched), StopReason::none);
  EXPECT_EQ(theta_of(untouched.p), start);
  EXPECT_EQ(known_ctx.budget.evaluations(), 0);
}

TEST_F(Stages, AStartDampedNegativelyOverTheRangeDropsThetaTwo) {
  const FitSettings settings;
  const FitContext ctx(window_, settings);
  FitState state = state_at(window_, truth_);
  state.range = {0.0, 100.0};
  start_with_positive_damping(ctx, state);
  EXPECT_EQ(state.p[kDampingSlope], truth_[kDampingSlope]);  // damped: kept
  state.p[kDampingSlope] = -state.p[kDamping] / 50.0;
  start_with_positive_damping(ctx, state);
  EXPECT_EQ(state.p[kDampingSlope], 0.0);
  FitSettings known;
  known.known[kDampingSlope] = true;
  const FitContext known_ctx(window_, known);
  state.p[kDampingSlope] = -1.0;
  start_with_positive_damping(known_ctx, state);
  EXPECT_EQ(state.p[kDampingSlope], -1.0);
}

TEST_F(Stages, MechanicalFitsThetaOneToFourOnX) {
  const FitSettings settings;
  FitContext ctx(window_, settings);
  Vector6 start = truth_;
  for (const int i : kMechanicalTheta) start[i] *= i % 2 == 0 ? 1.1 : 0.9;
  FitState state = state_at(window_, start);
  state.range = {0.0, 100.0};
  ASSERT_EQ(fit_mechanical(ctx, state), StopReason::none);
  std::printf("mechanical stage: theta1..4 %.3g off\n", mechanical_error(state.p, truth_));
  EXPECT_LT(mechanical_error(state.p, truth_), 1e-6);
  EXPECT_EQ(state.p.segment<2>(kCooling), truth_.segment<2>(kCooling));
  EXPECT_EQ(state.p[kTbar0], window_.front().tbar);
  EXPECT_LT(state.noise.x, 1e-24);  // noise-free: x's variance at its floor
}

// Under sensor noise the joint stage must find θ within a few σ of the truth and each channel's
// noise standard deviation to a few %.
TEST(JointStage, FitsEverySlotAndTheNoiseLevels) {
  constexpr double kSigmaX = 1e-7, kSigmaT = 1e-3;
  const auto w = test::paper_record(60.0, {.x = kSigmaX, .tbar = kSigmaT, .seed = 4});
  const Vector6 truth = test::theta_of(test::paper_actuator());
  const FitSettings settings;
  FitContext ctx(w, settings);
  FitState state = state_at(w, truth * 1.02);
  state.range = {0.0, 100.0};
  ASSERT_EQ(fit_joint(ctx, state), StopReason::none);
  std::printf("joint stage: %s, sigma_x %.4g (true %.4g), sigma_T %.4g (true %.4g)\n",
              state.joint.message, std::sqrt(state.noise.x), kSigmaX, std::sqrt(state.noise.tbar),
              kSigmaT);
  EXPECT_TRUE(state.joint.converged) << state.joint.message;
  EXPECT_NEAR(std::sqrt(state.noise.x), kSigmaX, 0.03 * kSigmaX);
  EXPECT_NEAR(std::sqrt(state.noise.tbar), kSigmaT, 0.03 * kSigmaT);
  EXPECT_EQ(state.sample_timing_sigma_s, 0.0);
  // θ within 4 Cramér–Rao σ of the truth.
  const Matrix6 crb =
      cramer_rao_bound(w, truth, Eigen::Vector3d::Zero(), Vector2(kSigmaX, kSigmaT));
  for (int i = 0; i < kThetaSize; ++i)
    EXPECT_LT(std::abs(state.p[i] - truth[i]), 4.0 * std::sqrt(crb(i, i))) << i;
}

// With the samples' timing jitter the joint stage estimates its variance beside the noise's.
TEST(JointStage, EstimatesTheSamplesTimingJitter) {
  const auto params = test::paper_actuator();
  auto w = test::link_record(params, 60.0);
  constexpr double kJitter = 41e-6;
  std::mt19937_64 rng(11);
  std::normal_distribution<double> gauss(0.0, kJitter);
  for (auto& s : w) s.t += gauss(rng);
  FitSettings settings;
  settings.sample_timing_jitter = true;
  FitContext ctx(w, settings);
  FitState state = state_at(w, test::theta_of(params));
  state.range = {0.0, 100.0};
  ASSERT_EQ(fit_joint(ctx, state), StopReason::none);
  std::printf("joint stage with jitter: %.2f us\n", state.sample_timing_sigma_s * 1e6);
  EXPECT_TRUE(state.noise.timing_estimated);
  EXPECT_NEAR(state.sample_timing_sigma_s, kJitter, 0.1 * kJitter);
}

// A pass's channels reweighted are the pass at the new weights: what the joint stage's next round
// starts from instead of simulating it again.
TEST(ResidualPass, ReweightedIsThePassAtTheOtherWeights) {
  const auto w = test::paper_record(20.0, {.x = 1e-7, .tbar = 1e-3, .seed = 6});
  const ParamVector p =
      param_vector(test::theta_of(test::paper_actuator()) * 1.03, Eigen::Vector3d::Zero());
  PassSettings from;
  from.weight = {1e12, 1e6};
  PassSettings to = from;
  to.weight = {3.7e13, 2.2e5};
  const PassResult pass = residual_pass(w, p, from);
  ASSERT_TRUE(pass.channels.has_value());
  const std::optional<PassResult> moved = reweighted(pass, from.weight, to.weight);
  ASSERT_TRUE(moved.has_value());
  const PassResult fresh = residual_pass(w, p, to);
  EXPECT_NEAR(moved->cost, fresh.cost, 1e-12 * fresh.cost);
  EXPECT_LT((moved->jtwj - fresh.jtwj).norm(), 1e-12 * fresh.jtwj.norm());
  EXPECT_LT((moved->jtwr - fresh.jtwr).norm(), 1e-12 * fresh.jtwr.norm());
  EXPECT_EQ(moved->rss, fresh.rss);
  EXPECT_EQ(moved->lag1, fresh.lag1);
  // A channel the pass left out cannot be weighted in.
  PassSettings thermal = from;
  thermal.weight[0] = 0.0;
  EXPECT_FALSE(reweighted(residual_pass(w, p, thermal), thermal.weight, to.weight).has_value());
}

// A fit whose covariance waited, concluded, is the fit that did not wait: the same passes, θ, σ
// and verdict; before it is concluded, it carries what the placement of switches reads.
TEST(CovarianceStage, AFitWhoseCovarianceWaitedConcludesAsTheFitThatDidNot) {
  const auto w = test::paper_record(30.0, {.x = 1e-7, .tbar = 1e-3, .seed = 8});
  const Vector6 start = test::theta_of(test::paper_actuator()) * 1.1;
  const FitSettings settings;
  const FitResult full = fit_staged(w, start, settings);
  ASSERT_TRUE(full.converged) << full.message;
  std::optional<PendingCovariance> pending;
  FitResult waited = fit_staged_deferring_covariance(w, start, settings, pending);
  ASSERT_TRUE(pending.has_value());
  EXPECT_TRUE(waited.validated);
  EXPECT_TRUE(waited.converged);
  EXPECT_EQ(waited.evaluations, full.evaluations - 1);  // the covariance's pass, not yet run
  EXPECT_EQ(waited.theta, full.theta);
  EXPECT_EQ(waited.noise_sigma, full.noise_sigma);
  EXPECT_EQ(waited.hac_lags, full.hac_lags);
  EXPECT_EQ(waited.sigma, Vector6::Zero());
  conclude_deferred(*pending, waited);
  EXPECT_EQ(waited.evaluations, full.evaluations);
  EXPECT_EQ(waited.iterations, full.iterations);
  EXPECT_EQ(waited.sigma, full.sigma);
  EXPECT_EQ(waited.covariance, full.covariance);
  EXPECT_EQ(waited.stop, full.stop);
  EXPECT_EQ(waited.converged, full.converged);
  EXPECT_EQ(waited.validation.thermal.verdict, full.validation.thermal.verdict);
  EXPECT_EQ(waited.validation.mechanical.verdict, full.validation.mechanical.verdict);
}

// At the truth with the true noise levels, the white covariance is the Cramér–Rao bound of the
// same window (the same JᵀWJ), and Newey–West's agrees with it on white noise.
TEST(CovarianceStage, IsTheCramerRaoBoundAtTheTruth) {
  constexpr double kSigmaX = 1e-7, kSigmaT = 1e-3;
  const auto w = test::paper_record(60.0, {.x = kSigmaX, .tbar = kSigmaT, .seed = 5});
  const Vector6 truth = test::theta_of(test::paper_actuator());
  const FitSettings settings;
  FitContext ctx(w, settings);
  FitState state;
  state.p = param_vector(truth, Eigen::Vector3d::Zero());  // the record starts at rest
  state.noise.x = kSigmaX * kSigmaX;
  state.noise.tbar = kSigmaT * kSigmaT;
  FitResult result;
  const CovarianceOutcome out = estimate_covariance(ctx, state, result);
  ASSERT_EQ(out.stop, StopReason::none);
  EXPECT_TRUE(out.definite);
  EXPECT_EQ(ctx.budget.evaluations(), 1);
  EXPECT_EQ(result.evaluations, 1);
  const Matrix6 crb =
      cramer_rao_bound(w, truth, Eigen::Vector3d::Zero(), Vector2(kSigmaX, kSigmaT));
  for (int i = 0; i < kThetaSize; ++i) {
    EXPECT_NEAR(result.covariance_white(i, i), crb(i, i), 1e-9 * crb(i, i)) << i;
    EXPECT_NEAR(result.sigma_white[i], std::sqrt(crb(i, i)), 1e-9 * std::sqrt(crb(i, i)));
    // Newey–West's before the batch-means check: the white covariance on white noise.
    EXPECT_NEAR(result.sigma[i] / result.sigma_inflation[i] / result.sigma_white[i], 1.0, 0.2) << i;
  }
  EXPECT_GT(result.hac_lags, 0);
  EXPECT_NEAR(result.noise_sigma[0], kSigmaX, 0.05 * kSigmaX);
  EXPECT_NEAR(result.noise_sigma[1], kSigmaT, 0.05 * kSigmaT);
  EXPECT_NEAR(result.residual_rms[1], kSigmaT, 0.05 * kSigmaT);
}

// An estimated delay's σ adds to θ's covariance: never less than without it.
TEST(CovarianceStage, AnEstimatedDelaysSigmaWidensTheCovariance) {
  const auto w = test::paper_record(60.0, {.x = 1e-7, .tbar = 1e-3, .seed = 6});
  const Vector6 truth = test::theta_of(test::paper_actuator());
  const FitSettings settings;
  FitContext ctx(w, settings);
  FitState state;
  state.p = param_vector(truth, Eigen::Vector3d::Zero());
  state.noise.x = 1e-14;
  state.noise.tbar = 1e-6;
  FitResult without;
  ASSERT_EQ(estimate_covariance(ctx, state, without).stop, StopReason::none);
  state.delay.ok = true;
  state.delay.sigma = 1e-6;
  FitResult with;
  ASSERT_EQ(estimate_covariance(ctx, state, with).stop, StopReason::none);
  for (int i = 0; i < kThetaSize; ++i) {
    EXPECT_GE(with.sigma[i], without.sigma[i]) << i;
    EXPECT_GE(with.sigma_white[i], without.sigma_white[i]) << i;
  }
  EXPECT_GT(with.sigma[kHeating], without.sigma[kHeating]);
}

TEST(Verdict, NamesTheFirstCheckTheSolutionFails) {
  const auto& w = test::cached_paper_record(2.0);
  const FitSettings settings;
  const FitContext ctx(w, settings);
  FitState state = state_at(w, test::theta_of(test::paper_actuator()));
  state.range = {0.0, 50.0};
  CovarianceOutcome covariance;
  covariance.definite = true;
  covariance.model_range = {0.0, 60.0};
  EXPECT_EQ(verdict(ctx, state, covariance), StopReason::none);
  state.delay.at_limit = true;
  EXPECT_EQ(verdict(ctx, state, covariance), StopReason::input_delay_at_limit);
  covariance.definite = false;
  EXPECT_EQ(verdict(ctx, state, covariance), StopReason::covariance_singular);
  // A fast pole of 1e5 rad/s at 1 kHz sampling: e⁻¹⁰⁰ per interval.
  state.p[kDamping] = 1e5;
  EXPECT_EQ(verdict(ctx, state, covariance), StopReason::fast_pole_unresolved);
  // Damping negative at the hot end of the solution's range (wider than the thermal stage's).
  state.p[kDampingSlope] = -state.p[kDamping] / 55.0;
  EXPECT_EQ(verdict(ctx, state, covariance), StopReason::model_unstable);
}

}  // namespace
}  // namespace scp::refine

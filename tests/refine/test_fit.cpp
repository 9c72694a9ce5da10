// The staged output-error fit on noise-free records: it must find θ to 1e-6 from bad starts.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "refine/fit.hpp"
#include "tests/refine/record.hpp"

namespace scp::refine {
namespace {

double max_relative_error(const Vector6& estimate, const Vector6& truth) {
  return ((estimate - truth).cwiseQuotient(truth)).cwiseAbs().maxCoeff();
}

// θ1..θ4 only.
double mechanical_error(const Vector6& estimate, const Vector6& truth) {
  return ((estimate - truth).cwiseQuotient(truth)).head<4>().cwiseAbs().maxCoeff();
}

class PaperRecord : public ::testing::Test {
 protected:
  const std::vector<WindowSample>* window_ = &test::cached_paper_record(300.0);
  const Vector6 truth_ = test::theta_of(test::paper_actuator());
};

TEST_F(PaperRecord, ConvergesFromThirtyPercentOff) {
  for (double sign : {1.0, -1.0}) {
    Vector6 start = truth_;
    for (int i = 0; i < 6; ++i) start[i] *= 1.0 + sign * (i % 2 == 0 ? 0.3 : -0.3);
    const FitResult r = fit(*window_, start);
    const double err = max_relative_error(r.theta, truth_);
    std::printf("±30 %% (sign %+g): %s after %d iterations, max rel error %.3g\n", sign, r.message,
                r.iterations, err);
    EXPECT_TRUE(r.converged) << r.message;
    EXPECT_LT(err, 1e-6);
  }
}

TEST_F(PaperRecord, ConvergesFromThePaperLawsBiasedStart) {
  Vector6 start = truth_;
  start.head<4>() *= 0.17;
  start[5] *= 1.001;
  const FitResult r = fit(*window_, start);
  const double err = max_relative_error(r.theta, truth_);
  std::printf("x0.17 start: %s after %d iterations, max rel error %.3g\n", r.message, r.iterations,
              err);
  EXPECT_TRUE(r.converged) << r.message;
  EXPECT_LT(err, 1e-6);
}

TEST_F(PaperRecord, ConvergesFromZero) {
  const FitResult r = fit(*window_, Vector6::Zero());
  const double err = max_relative_error(r.theta, truth_);
  std::printf("zero start: %s after %d iterations, max rel error %.3g\n", r.message, r.iterations,
              err);
  EXPECT_TRUE(r.converged) << r.message;
  EXPECT_LT(err, 1e-6);
}

}  // namespace
}  // namespace scp::refine

namespace scp::refine {
namespace {

TEST(Fit, UnderdampedFasterActuatorConvergesNoiseFree) {
  const auto params = test::underdamped_actuator();
  const Vector6 truth = test::theta_of(params);
  const auto w = test::paper_record(120.0, {}, params);
  for (double sign : {1.0, -1.0}) {
    Vector6 start = truth;
    for (int i = 0; i < 6; ++i) start[i] *= 1.0 + sign * (i % 2 == 0 ? 0.3 : -0.3);
    const FitResult r = fit(w, start);
    const double err = max_relative_error(r.theta, truth);
    std::printf("underdamped ±30 %% (sign %+g): %s after %d iterations, max rel error %.3g\n", sign,
                r.message, r.iterations, err);
    EXPECT_TRUE(r.converged) << r.message;
    EXPECT_LT(err, 1e-6);
  }
  const FitResult r = fit(w, Vector6::Zero());
  std::printf("underdamped zero start: %s, max rel error %.3g\n", r.message,
              max_relative_error(r.theta, truth));
  EXPECT_TRUE(r.converged) << r.message;
  EXPECT_LT(max_relative_error(r.theta, truth), 1e-6);
}

// The daemon's sliding window starts mid-experiment: hot, moving, x0 and T̄0 far from zero.
TEST(Fit, WindowStartingMidExperiment) {
  const auto& full = test::cached_paper_record(300.0);
  const std::vector<WindowSample> w(full.begin() + 100000, full.begin() + 200001);
  const Vector6 truth = test::theta_of(test::paper_actuator());
  Vector6 start = truth;
  start.head<4>() *= 0.17;
  const FitResult r = fit(w, start);
  std::printf("window 100..200 s: %s, max rel error %.3g, T0 %.6f (data %.6f)\n", r.message,
              max_relative_error(r.theta, truth), r.initial_state[2], w[0].tbar);
  EXPECT_TRUE(r.converged) << r.message;
  EXPECT_LT(max_relative_error(r.theta, truth), 1e-6);
  EXPECT_NEAR(r.initial_state[0], w[0].x, 1e-9 * std::abs(w[0].x));
  EXPECT_NEAR(r.initial_state[2], w[0].tbar, 1e-9 * w[0].tbar);
  EXPECT_DOUBLE_EQ(r.t_begin, 100.0);
  EXPECT_DOUBLE_EQ(r.t_end, 200.0);
  EXPECT_EQ(r.samples, 100001u);
}

TEST(Fit, KnownParametersAreHeldAndGetNoSigma) {
  const auto& w = test::cached_paper_record(60.0);
  const Vector6 truth = test::theta_of(test::paper_actuator());
  Vector6 start = truth * 1.2;
  start[2] = truth[2];  // θ3 = k/m known exactly
  FitSettings settings;
  settings.known[2] = true;
  const FitResult r = fit(w, start, settings);
  EXPECT_TRUE(r.converged) << r.message;
  EXPECT_EQ(r.theta[2], truth[2]);
  EXPECT_EQ(r.sigma[2], 0.0);
  EXPECT_LT(max_relative_error(r.theta, truth), 1e-6);
}

TEST(Fit, UnusableWindowsAreRefusedWithAReason) {
  const auto& good = test::cached_paper_record(60.0);
  const Vector6 truth = test::theta_of(test::paper_actuator());
  std::vector<WindowSample> w(good.begin(), good.begin() + 2);
  FitResult r = fit(w, truth);
  EXPECT_FALSE(r.converged);
  EXPECT_STREQ(r.message, "window has fewer than 3 samples");
  w.assign(good.begin(), good.begin() + 100);
  w[50].t = w[49].t;
  r = fit(w, truth);
  EXPECT_FALSE(r.converged);
  EXPECT_STREQ(r.message, "window times are not strictly increasing");
  w.assign(good.begin(), good.begin() + 100);
  w[10].x = std::nan("");
  r = fit(w, truth);
  EXPECT_FALSE(r.converged);
  EXPECT_STREQ(r.message, "window has a non-finite sample");
  // No heating at all: the thermal and mechanical blocks are not excited.
  w.assign(good.begin(), good.begin() + 1000);
  for (auto& s : w) s.voltage = 0.0, s.x = 0.0, s.tbar = 0.0;
  r = fit(w, truth);
  EXPECT_FALSE(r.converged);
  std::printf("unexcited window: %s\n", r.message);
}

TEST(Fit, NonUniformSamplingWithMidIntervalVoltage) {
  const auto params = test::paper_actuator();
  const Vector6 truth = test::theta_of(params);
  const auto w = test::link_record(params, 120.0);
  Vector6 start = truth * 1.2;
  const FitResult r = fit(w, start);
  std::printf("jittered 10 ms link, 120 s: %s, max rel error %.3g\n", r.message,
              max_relative_error(r.theta, truth));
  EXPECT_TRUE(r.converged) << r.message;
  EXPECT_LT(max_relative_error(r.theta, truth), 1e-6);
}

// A link whose recorded switch instants are 150 µs early (an output latency nobody configured):
// the common scale of θ1..θ4 is a 0.8 ms lag between heating and motion, so taking the instants
// as exact costs θ1..θ4 ~15 %; estimated from T̄, the delay comes out to a fraction of a µs and
// θ to 1e-5.
TEST(Fit, AnUnmodelledOutputLatencyIsEstimatedFromTemperature) {
  const auto params = test::paper_actuator();
  const Vector6 truth = test::theta_of(params);
  constexpr double kLatency = 150e-6;
  const auto w = test::late_link_record(params, 120.0, kLatency);
  const FitResult taken = fit(w, truth * 1.1);
  std::printf("instants taken as recorded: %s, theta1..4 rel. error %.3g\n", taken.message,
              mechanical_error(taken.theta, truth));
  EXPECT_FALSE(taken.input_delay_estimated);
  EXPECT_GT(mechanical_error(taken.theta, truth), 0.05);

  FitSettings settings;
  settings.max_input_delay_s = 2e-3;
  const FitResult r = fit(w, truth * 1.1, settings);
  std::printf("delay estimated: %s, %.4f us (sigma %.4f us), max rel error %.3g\n", r.message,
              r.input_delay_s * 1e6, r.input_delay_sigma_s * 1e6,
              max_relative_error(r.theta, truth));
  EXPECT_TRUE(r.converged) << r.message;
  ASSERT_TRUE(r.input_delay_estimated);
  EXPECT_NEAR(r.input_delay_s, kLatency, 0.05e-6);
  EXPECT_GT(r.input_delay_sigma_s, 0.0);
  EXPECT_LT(max_relative_error(r.theta, truth), 1e-5);
  // With sensor noise, σ carries the delay's uncertainty: at least what the fit at the true,
  // known delay claims.
  const auto noisy = test::with_noise(w, {.x = 1e-8, .tbar = 1e-3, .seed = 3});
  const FitResult estimated = fit(noisy, truth, settings);
  auto corrected = noisy;
  for (auto& s : corrected) s.voltage_since += kLatency;
  const FitResult known = fit(corrected, truth);
  std::printf("noisy: delay %.3f us (sigma %.3f us); sigma theta1 %.3g known, %.3g estimated\n",
              estimated.input_delay_s * 1e6, estimated.input_delay_sigma_s * 1e6, known.sigma[0],
              estimated.sigma[0]);
  ASSERT_TRUE(estimated.converged && known.converged) << estimated.message << known.message;
  for (int i = 0; i < 6; ++i) EXPECT_GE(estimated.sigma[i], known.sigma[i] * (1 - 1e-6)) << i;
  EXPECT_NEAR(estimated.input_delay_s, kLatency, 5 * estimated.input_delay_sigma_s);
}

// The daemon's default: the bench's nuisance terms estimated beside the delay. To first order a
// sensor's lag and the voltage's delay move T̄'s reading alike (by −τs·dT̄/dt and −d·dT̄/dt), and
// x cannot tell the delay from θ1..θ4's common scale: a lag left free beside the delay let the
// delay's search run to its limit, the lag to minus that, and θ1..θ4 to 4 times their size.
TEST(Fit, TheDelayIsEstimatedBesideTheBenchsNuisanceTerms) {
  const auto params = test::paper_actuator();
  const Vector6 truth = test::theta_of(params);
  constexpr double kLatency = 150e-6;
  const auto w = test::late_link_record(params, 120.0, kLatency);
  FitSettings settings;
  settings.max_input_delay_s = 5e-3;
  settings.nuisance.x_zero.fixed = false;
  settings.nuisance.ambient_offset.fixed = false;
  settings.nuisance.ambient_drift.fixed = false;
  settings.nuisance.sensor_lag.fixed = false;
  const FitResult r = fit(w, truth * 1.1, settings);
  std::printf(
      "delay beside the nuisance terms: %s, %.4f us (sigma %.4f us), lag %.3g s%s, max rel "
      "error %.3g\n",
      r.message, r.input_delay_s * 1e6, r.input_delay_sigma_s * 1e6, r.nuisance.sensor_lag.value,
      r.sensor_lag_held ? " (held)" : "", max_relative_error(r.theta, truth));
  EXPECT_TRUE(r.converged) << r.message;
  EXPECT_NEAR(r.input_delay_s, kLatency, 0.05e-6);
  EXPECT_LT(std::abs(r.nuisance.sensor_lag.value), 1e-7);
  EXPECT_LT(max_relative_error(r.theta, truth), 1e-5);
}

// A DAC that switches at the samples (the simulated plant): the delay cannot be negative there,
// and the estimate finds none.
TEST(Fit, ASampleSynchronousDacHasNoDelay) {
  const auto& w = test::cached_paper_record(60.0);
  const Vector6 truth = test::theta_of(test::paper_actuator());
  FitSettings settings;
  settings.max_input_delay_s = 1e-3;
  const FitResult r = fit(w, truth * 1.2, settings);
  std::printf("sample-synchronous DAC: %s, delay %.4f us (sigma %.4f us), max rel error %.3g\n",
              r.message, r.input_delay_s * 1e6, r.input_delay_sigma_s * 1e6,
              max_relative_error(r.theta, truth));
  EXPECT_TRUE(r.converged) << r.message;
  EXPECT_GE(r.input_delay_s, -1e-12);
  EXPECT_LT(r.input_delay_s, 0.05e-6);
  EXPECT_LT(max_relative_error(r.theta, truth), 1e-5);
}

// The link's samples stamped with a random error (41 µs RMS here, what a 0.2 ms frame jitter leaves
// in a transaction's midpoint): x's residual is ẋ times it, the along-trajectory part the fit
// weights out once it has estimated the jitter (FitSettings::sample_timing_jitter).
TEST(Fit, TheSamplesTimingJitterIsEstimatedAndWeightedOut) {
  const auto params = test::paper_actuator();
  const Vector6 truth = test::theta_of(params);
  auto w = test::link_record(params, 120.0);
  constexpr double kJitter = 41e-6;
  std::mt19937_64 rng(11);
  std::normal_distribution<double> gauss(0.0, kJitter);
  for (auto& s : w) s.t += gauss(rng);
  const FitResult plain = fit(w, truth * 1.1);
  FitSettings settings;
  settings.sample_timing_jitter = true;
  const FitResult r = fit(w, truth * 1.1, settings);
  std::printf(
      "stamps with %.0f us of jitter: taken as exact %.3g (sigma %.3g), jitter estimated "
      "%.2f us: %.3g (sigma %.3g), %s\n",
      kJitter * 1e6, mechanical_error(plain.theta, truth), plain.sigma[0] / truth[0],
      r.sample_timing_sigma_s * 1e6, mechanical_error(r.theta, truth), r.sigma[0] / truth[0],
      r.message);
  EXPECT_TRUE(r.converged) << r.message;
  EXPECT_NEAR(r.sample_timing_sigma_s, kJitter, 0.05 * kJitter);
  EXPECT_LT(mechanical_error(r.theta, truth), mechanical_error(plain.theta, truth) / 3.0);
  // Not asserted: σ covering the error. With noise-free sensors the noise variances come out
  // near 0 and what is left (the linearization of each sample's shift, O(jitter²)) is no noise
  // that σ counts: measured 2.9e-5 against σ 5e-6 (docs/numerics.md, "Time on a real link").
}

// A loaded machine now and then runs the loop thread late between a reply and its stamp, and a
// stamp the gate does not catch is off by milliseconds, not tens of µs (docs/numerics.md). With
// 0.3 % of the stamps displaced by 1-3 ms beside the link's 41 µs of jitter, the robust weights
// (FitSettings::outlier_threshold) must flag the displaced stamps, keep them from inflating the
// jitter estimate (it is published, and it sets every sample's weight), and bring θ1..θ4 closer
// than the fit without them; on undisplaced stamps they must set aside only a Gaussian tail.
TEST(Fit, StampsALoadSpikeDisplacedAreDownWeighted) {
  const auto params = test::paper_actuator();
  const Vector6 truth = test::theta_of(params);
  const auto clean = test::link_record(params, 120.0);
  constexpr double kJitter = 41e-6;
  std::mt19937_64 rng(24);
  std::normal_distribution<double> gauss(0.0, kJitter);
  std::uniform_real_distribution<double> spike(1e-3, 3e-3);
  std::bernoulli_distribution spiked(0.003);
  auto jittered = clean;
  for (auto& s : jittered) s.t += gauss(rng);
  auto w = jittered;
  std::size_t spikes = 0;
  for (std::size_t k = 1; k + 1 < w.size(); ++k) {
    if (!spiked(rng)) continue;
    // Within the neighbours' stamps, so t still increases.
    w[k].t = std::min(w[k].t + spike(rng), 0.5 * (w[k].t + w[k + 1].t));
    ++spikes;
  }
  FitSettings settings;
  settings.sample_timing_jitter = true;
  const FitResult plain = fit(w, truth * 1.1, settings);
  settings.outlier_threshold = kOutlierThreshold2d;
  const FitResult robust = fit(w, truth * 1.1, settings);
  const FitResult on_clean = fit(jittered, truth * 1.1, settings);
  std::printf(
      "%zu of %zu stamps displaced 1-3 ms: theta1..4 %.3g (sigma %.3g, jitter %.1f us) without "
      "robust weights, %.3g (sigma %.3g, jitter %.1f us, %zu down-weighted) with; on the "
      "undisplaced stamps %.3g (%zu down-weighted)\n",
      spikes, w.size(), mechanical_error(plain.theta, truth), plain.sigma[0] / truth[0],
      plain.sample_timing_sigma_s * 1e6, mechanical_error(robust.theta, truth),
      robust.sigma[0] / truth[0], robust.sample_timing_sigma_s * 1e6, robust.outliers,
      mechanical_error(on_clean.theta, truth), on_clean.outliers);
  ASSERT_GT(spikes, 20u);
  EXPECT_TRUE(robust.converged) << robust.message;
  EXPECT_TRUE(on_clean.converged) << on_clean.message;
  // Measured (seeds 23-25): 112-133 µs without, 40.4-41.1 µs with.
  EXPECT_GT(plain.sample_timing_sigma_s, 2.0 * kJitter);
  EXPECT_NEAR(robust.sample_timing_sigma_s, kJitter, 0.1 * kJitter);
  // Measured: 1.4-4.7e-5 without, 4e-7..3e-5 with (the noise-free floor, where a few samples'
  // leverage shows).
  EXPECT_LT(mechanical_error(robust.theta, truth), mechanical_error(plain.theta, truth));
  EXPECT_GE(robust.outliers, spikes * 9 / 10);
  // Gaussian stamps: ~1 % of samples lie beyond the threshold.
  EXPECT_LT(on_clean.outliers, w.size() / 50);
  EXPECT_LT(robust.outliers, spikes + w.size() / 50);
}

// The landings' stamps carry a link's jitter too, and a landing off by δ puts θ6·ΔV²·δ into T̄
// that reaches x through T̄ for seconds: on the emulated RTU link it was what held θ1..θ4 at
// 2-5e-3 (docs/numerics.md, "Time on a real link"). With FitSettings::landing_timing_jitter the
// fit runs a Kalman filter on [x, ẋ, T̄] for it (refine/landing_filter.hpp). Over four links
// (seeds 1-4) the worst θ1..θ4 must come out well below the output-error fit's worst, each
// within 2.5σ, and the stamps' jitter must be estimated to 5 %.
TEST(Fit, TheLandingsJitterIsFilteredOutOfTbar) {
  const auto params = test::paper_actuator();
  const Vector6 truth = test::theta_of(params);
  constexpr double kJitter = 41e-6;
  double worst_plain = 0.0, worst = 0.0, worst_z = 0.0, mean_factor = 0.0, worst_jitter = 0.0;
  for (unsigned seed = 1; seed <= 4; ++seed) {
    const auto w = test::jittered_link_record(params, 120.0, kJitter, seed);
    FitSettings settings;
    settings.sample_timing_jitter = true;
    settings.outlier_threshold = kOutlierThreshold2d;
    const FitResult plain = fit(w, truth * 1.1, settings);
    settings.landing_timing_jitter = true;
    const FitResult filtered = fit(w, truth * 1.1, settings);
    const double plain_error = mechanical_error(plain.theta, truth);
    const double error = mechanical_error(filtered.theta, truth);
    // |error| / σ of θ1 (θ1..θ4 err together), θ5 and θ6.
    double z = error / (filtered.sigma[0] / truth[0]);
    for (int i : {4, 5})
      z = std::max(z, std::abs(filtered.theta[i] - truth[i]) / filtered.sigma[i]);
    std::printf(
        "seed %u, samples and landings stamped with %.0f us of jitter: theta1..4 %.3g (sigma "
        "%.3g) as output error, %.3g (sigma %.3g, jitter %.1f us) with T-bar filtered; worst "
        "error/sigma of theta1, 5, 6 %.2f, sigma scaled by batch means x%.2f (theta1)\n",
        seed, kJitter * 1e6, plain_error, plain.sigma[0] / truth[0], error,
        filtered.sigma[0] / truth[0], filtered.sample_timing_sigma_s * 1e6, z,
        filtered.sigma_inflation[0]);
    EXPECT_TRUE(filtered.converged) << filtered.message;
    worst_plain = std::max(worst_plain, plain_error);
    worst = std::max(worst, error);
    worst_z = std::max(worst_z, z);
    mean_factor += filtered.sigma_inflation[0] / 4;
    worst_jitter =
        std::max(worst_jitter, std::abs(filtered.sample_timing_sigma_s - kJitter) / kJitter);
  }
  // Measured: worst 2.6e-3 without, 1.7e-4 with (RMS over the seeds 9e-5), jitter 40.8-41.7 µs.
  // With a filter on T̄ alone (stop 23) the landings' errors it took out of T̄ stayed in x for
  // the slow pole's 0.7 s: worst 3.2e-4 (RMS 2.4e-4) and the jitter 35 µs in two seeds of four,
  // σx² held up by them. The batch-means check still scales σ by 2.7-3.0 here (error/σ of θ1,
  // θ5, θ6 then at most 1.4), though θ1..θ4's errors sit within Newey–West's σ (1.1e-4): a
  // slow component remains in the scores that these four seeds cannot place.
  EXPECT_LT(worst, worst_plain / 10.0);
  EXPECT_LT(worst_z, 2.5);
  EXPECT_LT(worst_jitter, 0.05);
  EXPECT_GT(mean_factor, 1.5);
}

// A link whose landing stamps wander slowly about the voltage's one delay (±10 µs, a new offset
// every 10 s, as a live link's 10 s means do): d̂ follows the wander's mean over the window, which
// T̄'s curvature, taking its residuals as white, does not see; the batch-means check on d
// (refine/delay_batch_means.hpp) does, and σ_d then covers d̂'s error.
TEST(Fit, TheDelaysSigmaSeesItsLandingStampsWander) {
  const auto params = test::paper_actuator();
  const Vector6 truth = test::theta_of(params);
  constexpr double kDelay = 20e-6;
  constexpr int kSeeds = 6;
  double z2_checked = 0.0, z2_curvature = 0.0;
  for (unsigned seed = 1; seed <= kSeeds; ++seed) {
    const auto w = test::jittered_link_record(
        params, 60.0, 41e-6, seed, {.delay = kDelay, .wander = 10e-6, .wander_block_s = 2.0});
    FitSettings settings;
    settings.sample_timing_jitter = true;
    settings.landing_timing_jitter = true;
    settings.outlier_threshold = kOutlierThreshold2d;
    settings.max_input_delay_s = 5e-3;
    const FitResult r = fit(w, truth * 1.1, settings);
    ASSERT_TRUE(r.input_delay_estimated) << r.message;
    const double error = r.input_delay_s - kDelay;
    const double curvature_sigma = r.input_delay_sigma_s / r.input_delay_sigma_inflation;
    std::printf(
        "seed %u: delay %.2f us, sigma %.2f us (x%.2f by batch means), error/sigma %.2f "
        "(%.2f with the curvature's sigma)\n",
        seed, r.input_delay_s * 1e6, r.input_delay_sigma_s * 1e6, r.input_delay_sigma_inflation,
        error / r.input_delay_sigma_s, error / curvature_sigma);
    EXPECT_TRUE(r.converged) << r.message;
    z2_checked += error * error / (r.input_delay_sigma_s * r.input_delay_sigma_s) / kSeeds;
    z2_curvature += error * error / (curvature_sigma * curvature_sigma) / kSeeds;
  }
  // Measured: RMS error/σ_d 1.15 checked, 2.6 with the curvature's σ_d (0.7 µs; the check scaled
  // it by 1.95-3.6 in every seed). The wander changes every 2 s here, inside the check's 3 s
  // batches: with 10 s blocks in this 60 s window the batches see six independent offsets, and
  // the same seeds give 1.5 (one seed's d̂ 5 µs off at 2.5σ). In 300 s (15 s batches), 10 s
  // blocks, 8 seeds: 0.8. Without the wander, 300 s: scaled by 1.5-3.0 in all 8 seeds, RMS
  // error/σ_d 1.5 → 0.8 (the landings' own jitter leaves slow errors in T̄ as well).
  EXPECT_GT(std::sqrt(z2_curvature), 1.6);
  EXPECT_GT(std::sqrt(z2_checked), 0.4);
  EXPECT_LT(std::sqrt(z2_checked), 1.3);
}

}  // namespace
}  // namespace scp::refine

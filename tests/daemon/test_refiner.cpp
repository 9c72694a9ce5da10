// The daemon's side of the refinement: the window, its breaks, when a fit is due, where the solver
// starts, and which estimate is best. The fit itself is a recording fake here (refine/ has its own
// tests); the end-to-end tests run the real one.

#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <optional>
#include <vector>

#include "daemon/analysis/refine/refiner.hpp"
#include "daemon/analysis/refine/sample_window.hpp"
#include "daemon/config/daemon_config.hpp"
#include "refine/model_simulator.hpp"
#include "refine/voltage_timing.hpp"

namespace scp::daemon::refine {
namespace {

using scp::refine::FitResult;
using scp::refine::FitSettings;
using scp::refine::WindowSample;

constexpr double kPeriod = 0.01;

WindowSample sample_at(double t) {
  return {t, 1e-3 * std::sin(t), 5.0, 1.0, -1e300};
}

TEST(SampleWindow, KeepsTheNewestSamplesContiguousInOrder) {
  SampleWindow w(4);
  EXPECT_TRUE(w.empty());
  for (int i = 0; i < 10; ++i) w.push(sample_at(i));
  ASSERT_EQ(w.size(), 4U);
  const auto s = w.samples();
  for (std::size_t i = 0; i < s.size(); ++i) EXPECT_EQ(s[i].t, 6.0 + static_cast<double>(i));
  EXPECT_DOUBLE_EQ(w.span_s(), 3.0);
  w.clear();
  EXPECT_TRUE(w.empty());
  w.push(sample_at(20));
  EXPECT_EQ(w.samples().size(), 1U);
  EXPECT_EQ(w.front().t, 20.0);
  EXPECT_DOUBLE_EQ(w.span_s(), 0.0);
}

// The ring stores each sample once and rotates on samples() when wrapped: the order must survive
// rotations interleaved with pushes and drops.
TEST(SampleWindow, StaysInOrderAcrossRotationsDropsAndPushes) {
  SampleWindow w(5);
  const auto expect_range = [&](double first, double last) {
    EXPECT_EQ(w.front().t, first);
    EXPECT_EQ(w.back().t, last);
    const auto s = w.samples();
    ASSERT_EQ(s.size(), static_cast<std::size_t>(last - first) + 1);
    for (std::size_t i = 0; i < s.size(); ++i) EXPECT_EQ(s[i].t, first + static_cast<double>(i));
    EXPECT_EQ(w.front().t, first);
    EXPECT_EQ(w.back().t, last);
  };
  for (int i = 0; i < 7; ++i) w.push(sample_at(i));
  expect_range(2, 6);
  w.drop_oldest();
  w.drop_oldest();
  expect_range(4, 6);
  w.push(sample_at(7));
  w.push(sample_at(8));
  expect_range(4, 8);
  w.push(sample_at(9));
  expect_range(5, 9);
  for (int i = 10; i < 13; ++i) w.push(sample_at(i));
  w.drop_oldest();
  expect_range(9, 12);
  expect_range(9, 12);  // a second call on a rotated ring changes nothing
}

// What the fake fit saw, call by call.
struct Call {
  double t_begin, t_end;
  std::size_t samples;
  Vector6 start;
  FitSettings settings;
  // The warm start the fit was offered (settings.warm points into the refiner), copied.
  std::optional<scp::refine::WarmStart> warm;
};

class RefinerTest : public ::testing::Test {
 protected:
  RefinerTest() {
    settings_.window_s = 10.0;
    settings_.interval_s = 2.0;
    settings_.min_window_s = 3.0;
    settings_.max_iterations = 17;
    settings_.hac_lags = 5;
    settings_.covariance_batches = 7;
    estimator_.theta0 << 1, 2, 3, 4, 5, 6;
    settings_.max_gap_s = 10 * kPeriod;
  }

  Refiner make() {
    return Refiner(
        settings_, estimator_, kPeriod,
        [this](std::span<const WindowSample> w, const Vector6& start, const FitSettings& s) {
          calls_.push_back({w.front().t, w.back().t, w.size(), start, s, std::nullopt});
          if (s.warm != nullptr) calls_.back().warm = *s.warm;
          FitResult r;
          r.warm = s.warm != nullptr && warm_accepted_;
          r.warm_fallback = s.warm == nullptr ? scp::refine::WarmFallback::not_requested
                            : r.warm          ? scp::refine::WarmFallback::none
                                              : scp::refine::WarmFallback::not_converged;
          r.initial_state = fitted_initial_;
          r.converged = converge_ && !stall_;
          r.message = r.converged ? "converged" : "gave up";
          if (stall_) r.stop = stop_;
          // Validated as refine::fit validates its solution: adequate, or what it says of a
          // model the window rejects.
          r.validated = true;
          r.validation.mechanical.verdict = r.validation.thermal.verdict =
              structure_ ? scp::refine::Verdict::kStructure : scp::refine::Verdict::kAdequate;
          r.iterations = 3;
          r.theta = fitted_theta_;
          r.sigma = fitted_sigma_;
          r.t_begin = w.front().t;
          r.t_end = w.back().t;
          r.samples = w.size();
          return r;
        });
  }

  // Samples every period in [from, to], segment `segment`; fits whenever due.
  void feed(Refiner& r, double from, double to, std::uint64_t segment = 0) {
    const auto n = static_cast<long>(std::llround((to - from) / kPeriod));
    for (long i = 0; i <= n; ++i) {
      const double t = from + static_cast<double>(i) * kPeriod;
      r.accept({sample_at(t), segment});
      if (r.due()) r.fit(paper_, t, 0);
    }
  }

  config::RefineSettings settings_;
  estimator::EstimatorConfig estimator_;
  std::vector<Call> calls_;
  bool converge_ = true;
  bool stall_ = false;
  scp::refine::StopReason stop_ = scp::refine::StopReason::stalled;  // of a fit that stalls
  bool structure_ = false;
  bool warm_accepted_ = true;
  scp::refine::InitialState fitted_initial_{1e-4, 0.0, 5.0};
  Vector6 fitted_theta_ = (Vector6() << 10, 20, 30, 40, 50, 60).finished();
  Vector6 fitted_sigma_ = Vector6::Constant(0.1);
  PaperEstimate paper_{{7, 7, 7, 7, 7, 7}, {1, 1, 1, 1, 1, 1}};
};

TEST_F(RefinerTest, FirstFitWhenTheWindowSpansMinWindowThenEveryInterval) {
  Refiner r = make();
  feed(r, 0.0, 2.99);
  EXPECT_TRUE(calls_.empty()) << "fitted before min_window_s";
  feed(r, 3.0, 9.0);
  ASSERT_EQ(calls_.size(), 4U);  // at 3, 5, 7, 9 s
  EXPECT_NEAR(calls_[0].t_end, 3.0, 1e-9);
  EXPECT_NEAR(calls_[1].t_end, 5.0, 1e-9);
  EXPECT_NEAR(calls_[3].t_end, 9.0, 1e-9);
  for (const Call& c : calls_) EXPECT_NEAR(c.t_begin, 0.0, 1e-9);
  EXPECT_EQ(r.view().fits, 4U);
  EXPECT_EQ(r.view().windows, 1U);
}

TEST_F(RefinerTest, TheWindowSlidesAndNeverHoldsMoreThanWindowS) {
  Refiner r = make();
  feed(r, 0.0, 30.0);
  ASSERT_FALSE(calls_.empty());
  const Call& last = calls_.back();
  EXPECT_NEAR(last.t_end, 29.0, 1e-9);
  EXPECT_NEAR(last.t_end - last.t_begin, settings_.window_s, kPeriod * 1.01);
  EXPECT_LE(last.samples, static_cast<std::size_t>(settings_.window_s / kPeriod) + 1);
}

// Missing samples (loop overruns within refine.max_gap_s) leave the window short of its capacity;
// it still never covers more than window_s of loop time.
TEST_F(RefinerTest, TheWindowCoversWindowSOfLoopTimeWhenSamplesAreMissing) {
  Refiner r = make();
  for (int i = 0; i <= 1500; ++i) {
    if (i % 2 == 1) continue;  // every other sample missing: a gap of 2 periods each time
    r.accept({sample_at(i * kPeriod), 0});
  }
  EXPECT_EQ(r.view().windows, 1U);
  EXPECT_NEAR(r.window().back().t - r.window().front().t, settings_.window_s, 1e-9);
  EXPECT_EQ(r.window().size(), 501U);
}

TEST_F(RefinerTest, ATimeGapStartsANewWindowThatWaitsForMinWindowAgain) {
  Refiner r = make();
  feed(r, 0.0, 4.0);
  ASSERT_EQ(calls_.size(), 1U);
  // More than refine.max_gap_s without a sample.
  feed(r, 4.0 + 11 * kPeriod, 6.0);
  EXPECT_EQ(calls_.size(), 1U) << "fitted across a gap or on a short window";
  EXPECT_EQ(r.view().windows, 2U);
  feed(r, 6.01, 8.0);
  ASSERT_EQ(calls_.size(), 2U);
  EXPECT_NEAR(calls_[1].t_begin, 4.0 + 11 * kPeriod, 1e-9);
}

TEST_F(RefinerTest, AGapWithinMaxGapPeriodsKeepsTheWindow) {
  Refiner r = make();
  feed(r, 0.0, 1.0);
  feed(r, 1.0 + 9 * kPeriod, 3.5);
  ASSERT_EQ(calls_.size(), 1U);
  EXPECT_NEAR(calls_[0].t_begin, 0.0, 1e-9);
  EXPECT_EQ(r.view().windows, 1U);
}

TEST_F(RefinerTest, ASegmentChangeOrANonFiniteSampleStartsANewWindow) {
  Refiner r = make();
  feed(r, 0.0, 2.0, 0);
  feed(r, 2.01, 4.0, 1);  // the loop dropped a sample, reset, or left RUNNING
  EXPECT_TRUE(calls_.empty());
  EXPECT_EQ(r.view().windows, 2U);
  WindowSample bad = sample_at(4.01);
  bad.tbar = std::numeric_limits<double>::quiet_NaN();
  r.accept({bad, 1});
  feed(r, 4.02, 6.5, 1);
  EXPECT_TRUE(calls_.empty());
  EXPECT_EQ(r.view().windows, 3U);
  feed(r, 6.51, 7.1, 1);
  ASSERT_EQ(calls_.size(), 1U);
  EXPECT_NEAR(calls_[0].t_begin, 4.02, 1e-9);
}

TEST_F(RefinerTest, SettingsAndKnownParametersReachTheFit) {
  estimator_.known = {false, false, true, false, false, false};
  Refiner r = make();
  feed(r, 0.0, 3.0);
  ASSERT_EQ(calls_.size(), 1U);
  const FitSettings& s = calls_[0].settings;
  EXPECT_EQ(s.max_iterations, 17);
  EXPECT_EQ(s.hac_lags, 5);
  EXPECT_EQ(s.covariance_batches, 7);
  EXPECT_TRUE(s.known[2]);
  EXPECT_FALSE(s.known[0]);
  // A known parameter starts (and stays) at theta0 whatever the seed.
  EXPECT_EQ(calls_[0].start[2], 3.0);
  EXPECT_EQ(calls_[0].start[0], 7.0);
}

TEST_F(RefinerTest, TheCancelFlagReachesTheFit) {
  std::atomic<bool> cancel{false};
  Refiner r = make();
  feed(r, 0.0, 3.0);
  r.set_cancel(&cancel);
  feed(r, 3.0 + kPeriod, 6.0);
  ASSERT_GE(calls_.size(), 2U);
  EXPECT_EQ(calls_.front().settings.cancel, nullptr);
  EXPECT_EQ(calls_.back().settings.cancel, &cancel);
}

TEST_F(RefinerTest, SeedIsThePaperLawThenThePreviousConvergedFit) {
  Refiner r = make();
  feed(r, 0.0, 3.0);
  ASSERT_EQ(calls_.size(), 1U);
  EXPECT_EQ(calls_[0].start, Vector6::Constant(7.0));
  EXPECT_EQ(r.view().seed, Seed::paper);
  feed(r, 3.01, 5.0);
  ASSERT_EQ(calls_.size(), 2U);
  EXPECT_EQ(calls_[1].start, fitted_theta_);
  EXPECT_EQ(r.view().seed, Seed::refined);
}

TEST_F(RefinerTest, APoorlyDeterminedFitIsNoSeed) {
  fitted_sigma_ = Vector6::Constant(15.0);  // above |θ̂1| = 10: θ1 not determined
  Refiner r = make();
  feed(r, 0.0, 3.0);
  feed(r, 3.01, 5.0);
  ASSERT_EQ(calls_.size(), 2U);
  EXPECT_TRUE(r.view().converged);
  EXPECT_EQ(calls_[1].start, Vector6::Constant(7.0));
  EXPECT_EQ(r.view().seed, Seed::paper);
}

TEST_F(RefinerTest, APoorlyDeterminedFitFromTheRefinedSeedIsRetriedFromThePaperLaw) {
  Refiner r = make();
  feed(r, 0.0, 3.0);  // well determined: the next seed is this fit
  fitted_sigma_ = Vector6::Constant(100.0);
  feed(r, 3.01, 5.0);
  ASSERT_EQ(calls_.size(), 3U);
  EXPECT_EQ(calls_[1].start, fitted_theta_);
  EXPECT_EQ(calls_[2].start, Vector6::Constant(7.0));  // the retry, from the paper law
}

TEST_F(RefinerTest, SeedIsTheta0WhenThePaperLawHasNothingYet) {
  paper_.theta_hat = {0, 0, 0, 0, 0, 0};
  converge_ = false;
  Refiner r = make();
  feed(r, 0.0, 3.0);
  ASSERT_EQ(calls_.size(), 1U);
  EXPECT_EQ(calls_[0].start, estimator_.theta0);
  EXPECT_EQ(r.view().seed, Seed::theta0);
  paper_.theta_hat[4] = std::numeric_limits<double>::quiet_NaN();
  paper_.theta_hat[0] = 5.0;
  feed(r, 3.01, 5.0);
  ASSERT_EQ(calls_.size(), 2U);
  EXPECT_EQ(calls_[1].start, estimator_.theta0) << "a non-finite paper θ̂ is no seed";
  // A fit that did not converge is no seed either.
  EXPECT_EQ(r.view().seed, Seed::theta0);
  EXPECT_EQ(r.view().converged_fits, 0U);
  EXPECT_FALSE(r.view().converged);
  EXPECT_STREQ(r.view().message.data(), "gave up");
}

// Every fit after a window's first is offered the previous fit as a warm start, its trajectory
// carried to the window's first sample: the previous fit's model simulated from its own first
// sample through the samples the window dropped since.
TEST_F(RefinerTest, EachFitIsOfferedThePreviousOneShiftedToItsWindow) {
  fitted_theta_ << 1247.0, 0.8, 1813.0, 0.1, 0.0594, 1.1;  // a stable model: the paper's
  Refiner r = make();
  feed(r, 0.0, 14.0);  // fits at 3, 5, …, 13 s; the window (10 s) slides from 10 s on
  ASSERT_EQ(calls_.size(), 6U);
  EXPECT_FALSE(calls_[0].warm.has_value()) << "the window's first fit has nothing to start from";
  for (std::size_t i = 1; i < calls_.size(); ++i) {
    ASSERT_TRUE(calls_[i].warm.has_value()) << i;
    EXPECT_EQ(calls_[i].warm->at.t, calls_[i].t_begin) << i;
    EXPECT_EQ(calls_[i].warm->theta, fitted_theta_) << i;
    EXPECT_TRUE(calls_[i].warm->converged) << i;
  }
  // The fit at 13 s starts at 3 s; the one before (11 s) started at 1 s, from fitted_initial_.
  const Call& last = calls_.back();
  ASSERT_NEAR(last.t_begin, 3.0, 1e-9);
  std::vector<WindowSample> dropped;
  for (int i = 100; i <= 300; ++i) dropped.push_back(sample_at(i * kPeriod));
  std::vector<scp::refine::ModelState> states(dropped.size());
  scp::refine::simulate(dropped, fitted_theta_, fitted_initial_, states);
  EXPECT_NEAR(last.warm->state[0], states.back().x, 1e-12);
  EXPECT_NEAR(last.warm->state[1], states.back().xdot, 1e-12);
  EXPECT_NEAR(last.warm->state[2], states.back().tbar, 1e-12);
  EXPECT_EQ(r.view().warm_fits, 5U);
  EXPECT_TRUE(r.view().warm);
  EXPECT_EQ(r.view().warm_fallback, scp::refine::WarmFallback::none);
}

TEST_F(RefinerTest, NoWarmStartWhereTheFitEstimatesTheLinksTiming) {
  settings_.estimate_link_timing = true;
  Refiner r = make();
  feed(r, 0.0, 5.0);
  ASSERT_EQ(calls_.size(), 2U);
  EXPECT_FALSE(calls_[1].warm.has_value());
  EXPECT_TRUE(calls_[1].settings.sample_timing_jitter);
}

TEST_F(RefinerTest, ABreakInTheDataDropsTheWarmStart) {
  Refiner r = make();
  feed(r, 0.0, 4.0);
  feed(r, 4.0 + 11 * kPeriod, 8.0);  // a gap beyond refine.max_gap_s
  ASSERT_EQ(calls_.size(), 2U);
  EXPECT_FALSE(calls_[1].warm.has_value());
  EXPECT_FALSE(r.view().warm);
  EXPECT_EQ(r.view().warm_fits, 0U);
}

TEST_F(RefinerTest, AWarmStartTheFitDeclinesIsCountedAsCold) {
  warm_accepted_ = false;
  Refiner r = make();
  feed(r, 0.0, 5.0);
  ASSERT_EQ(calls_.size(), 2U);
  EXPECT_TRUE(calls_[1].warm.has_value());
  EXPECT_FALSE(r.view().warm);
  EXPECT_EQ(r.view().warm_fallback, scp::refine::WarmFallback::not_converged);
  EXPECT_EQ(r.view().warm_fits, 0U);
}

// A window the model did not explain is refitted when it has more data, not every interval: a
// growing window that covered the thermal time constant 1/θ5 when full, a shorter one at four
// times its length, a full one when it has renewed. The first fit that does not stall restores
// the interval.
TEST_F(RefinerTest, AfterAFitThatStalledTheNextWaitsForMoreData) {
  settings_.window_s = 100.0;
  stall_ = true;
  // θ5 from the paper law's estimate, else (not positive there) from the fit's.
  const auto fit_ends = [&](double paper_theta5, double fitted_theta5) {
    calls_.clear();
    paper_.theta_hat[4] = paper_theta5;
    fitted_theta_[4] = fitted_theta5;
    Refiner r = make();
    feed(r, 0.0, 250.0);
    std::vector<double> ends;
    for (const Call& c : calls_) ends.push_back(std::round(c.t_end * 100.0) / 100.0);
    return ends;
  };
  const std::vector<double> fourfold{3.0, 12.0, 48.0, 100.0, 200.0};
  // 1/θ5 = 100 s: each growing window was shorter (3, 12, 48 s), then full, then renewed.
  EXPECT_EQ(fit_ends(0.01, 50.0), fourfold);
  // 1/θ5 = 4 s: the 3 s window was shorter, the 12 s one covered it.
  EXPECT_EQ(fit_ends(0.25, 50.0), (std::vector<double>{3.0, 12.0, 100.0, 200.0}));
  // No paper θ5: the fit's (here 1/θ5 = 100 s); neither positive: fourfold.
  EXPECT_EQ(fit_ends(0.0, 0.01), fourfold);
  EXPECT_EQ(fit_ends(0.0, -1.0), fourfold);
  paper_.theta_hat[4] = 0.01;
  calls_.clear();
  settings_.window_s = 10.0;
  Refiner r = make();
  feed(r, 0.0, 9.0);
  ASSERT_EQ(calls_.size(), 1U);  // at 3 s (span 3: fourfold is beyond full, so at 10 s)
  EXPECT_NEAR(calls_[0].t_end, 3.0, 1e-9);
  stall_ = false;
  feed(r, 9.01, 14.0);
  ASSERT_EQ(calls_.size(), 4U);  // at 10 s, then every interval again: 12 s, 14 s
  EXPECT_NEAR(calls_[1].t_end, 10.0, 1e-9);
  EXPECT_NEAR(calls_[2].t_end, 12.0, 1e-9);
  EXPECT_NEAR(calls_[3].t_end, 14.0, 1e-9);
  stall_ = true;
  feed(r, 14.01, 30.0);          // the window is full (10 s): a stalled fit waits for it to renew
  ASSERT_EQ(calls_.size(), 6U);  // at 16 s, then 26 s
  EXPECT_NEAR(calls_[4].t_end, 16.0, 1e-9);
  EXPECT_NEAR(calls_[5].t_end, 26.0, 1e-9);
}

// The same for every way a fit finds a window its model cannot explain: it spends its passes' or
// sub-steps' budget, or converges to a solution the validation rejects. An unusable window or a
// cancelled fit is not the model's failure: the next fit comes an interval later.
TEST_F(RefinerTest, AfterAFitThatFoundTheModelRejectedTheNextWaitsForTheWindowToFill) {
  using scp::refine::StopReason;
  struct Case {
    StopReason stop;
    bool structure;
    bool backs_off;
  };
  for (const Case c :
       {Case{StopReason::work_budget_spent, false, true},
        Case{StopReason::evaluation_budget_spent, false, true},
        Case{StopReason::model_unstable, false, true}, Case{StopReason::none, true, true},
        Case{StopReason::cancelled, false, false},
        Case{StopReason::window_too_short, false, false}}) {
    calls_.clear();
    stall_ = c.stop != StopReason::none;
    stop_ = c.stop;
    structure_ = c.structure;
    Refiner r = make();
    feed(r, 0.0, 9.0);
    const char* what = c.structure ? "structure verdict" : scp::refine::to_text(c.stop);
    if (c.backs_off) {
      ASSERT_EQ(calls_.size(), 1U) << what;  // at 3 s, the next at 10 s, as after a stall
      EXPECT_NEAR(calls_[0].t_end, 3.0, 1e-9) << what;
    } else {
      EXPECT_EQ(calls_.size(), 4U) << what;  // at 3 s, then every interval (2 s) to 9 s
    }
  }
}

TEST_F(RefinerTest, HasUnfittedDataOnlyWhenNewSamplesCameAfterTheLastFit) {
  Refiner r = make();
  feed(r, 0.0, 2.0);
  EXPECT_FALSE(r.has_unfitted_data()) << "shorter than min_window_s";
  feed(r, 2.01, 3.0);
  ASSERT_EQ(calls_.size(), 1U);
  EXPECT_FALSE(r.has_unfitted_data());
  feed(r, 3.01, 3.5);
  EXPECT_TRUE(r.has_unfitted_data());
  EXPECT_FALSE(r.due());
}

TEST_F(RefinerTest, DrainTakesEverythingFromTheRing) {
  auto ring = std::make_unique<HandOffRing>();
  for (int i = 0; i < 100; ++i) ASSERT_TRUE(ring->try_push({sample_at(i * kPeriod), 0}));
  Refiner r = make();
  EXPECT_EQ(r.drain(*ring), 100U);
  EXPECT_EQ(r.window().size(), 100U);
  EXPECT_EQ(ring->size_approx(), 0U);
}

TEST_F(RefinerTest, TheViewCarriesTheFitAndItsWindow) {
  Refiner r = make();
  feed(r, 0.0, 3.0);
  const RefinedView& v = r.view();
  EXPECT_TRUE(v.valid);
  EXPECT_TRUE(v.converged);
  EXPECT_EQ(v.iterations, 3);
  EXPECT_EQ(v.theta_hat[5], 60.0);
  EXPECT_EQ(v.sigma[0], 0.1);
  EXPECT_NEAR(v.t_end, 3.0, 1e-9);
  EXPECT_EQ(v.samples, 301U);
  EXPECT_NEAR(v.fitted_at_t, 3.0, 1e-9);
  EXPECT_EQ(v.interval_s, settings_.interval_s);
}

// Keeps a copy of the window each fit was handed over with.
class RecordingObserver : public FitObserver {
 public:
  void on_sample(const WindowSample&) noexcept override {}
  void on_fit(const FitResult&, std::span<const WindowSample> window, std::int64_t) override {
    window_.assign(window.begin(), window.end());
  }
  std::vector<WindowSample> window_;
};

// A log that writes the command issued at t (refine.voltage_interval: after), its outputs the
// model's own, noise-free. The fit reads the window with each row's voltage moved to the next row
// (refine::prepare_window); the paper law's validation, the fallback validation and the health
// observer must read it so too: then θ̂ reproduces T̄ to rounding. On the raw window each switch
// of V would leave a period's worth of heating in T̄'s residual (~0.1 °C).
TEST_F(RefinerTest, TheValidationsAndTheObserverReadTheWindowAsTheFitDid) {
  settings_.voltage_interval = scp::refine::VoltageInterval::after;
  Vector6 theta;
  theta << 1247, 0.8, 1813, 0.1, 0.0594, 1.1;
  const scp::refine::InitialState initial(0.0, 0.0, 0.5);
  std::vector<WindowSample> raw;
  for (int k = 0; k <= 300; ++k) {
    const double t = k * kPeriod;
    raw.push_back({t, 0.0, 0.0, (k / 50) % 2 == 0 ? 1.0 : 3.0, -1e300});
  }
  std::vector<WindowSample> storage;
  const auto prepared = scp::refine::prepare_window(raw, estimator::VoltageHold::zoh,
                                                    scp::refine::VoltageInterval::after, storage);
  std::vector<scp::refine::ModelState> states(raw.size());
  scp::refine::simulate(prepared, theta, initial, states);
  for (std::size_t k = 0; k < raw.size(); ++k) {
    raw[k].x = states[k].x;
    raw[k].tbar = states[k].tbar;
  }

  Refiner r(settings_, estimator_, kPeriod,
            [&](std::span<const WindowSample> w, const Vector6&, const FitSettings& s) {
              EXPECT_EQ(s.voltage_interval, scp::refine::VoltageInterval::after);
              FitResult f;
              f.converged = true;
              f.theta = theta;
              f.sigma = Vector6::Constant(1e-3);
              f.initial_state = initial;
              f.voltage_interval = scp::refine::VoltageInterval::after;
              f.validated = false;  // the daemon validates it (validate_fit)
              f.samples = w.size();
              return f;
            });
  RecordingObserver observer;
  r.set_observer(&observer);
  for (const WindowSample& w : raw) r.accept({w, 0});
  for (std::size_t i = 0; i < 6; ++i) paper_.theta_hat[i] = theta[static_cast<Eigen::Index>(i)];
  const RefinedView& v = r.fit(paper_, raw.back().t, 0);

  ASSERT_TRUE(v.paper_validated);
  EXPECT_LT(v.paper_validation.thermal.residual_rms, 1e-9);
  EXPECT_LT(v.paper_validation.mechanical.residual_rms, 1e-12);
  ASSERT_TRUE(v.validated);
  EXPECT_LT(v.validation.thermal.residual_rms, 1e-9);
  EXPECT_LT(v.validation.mechanical.residual_rms, 1e-12);
  ASSERT_EQ(observer.window_.size(), raw.size());
  for (std::size_t k = 1; k < raw.size(); ++k) {
    EXPECT_EQ(observer.window_[k].voltage, raw[k - 1].voltage) << k;
  }
}

TEST(RefinedIsBest, OnlyARecentConvergedFitWithFiniteSigma) {
  RefinedView v;
  v.interval_s = 10.0;
  EXPECT_FALSE(refined_is_best(v, 0.0)) << "no fit yet";
  v.valid = true;
  v.converged = true;
  v.fitted_at_t = 100.0;
  v.theta_hat = {1, 2, 3, 4, 5, 6};
  v.sigma = {0.1, 0.1, 0.1, 0.1, 0.1, 0.0};
  EXPECT_TRUE(refined_is_best(v, 100.0));
  EXPECT_TRUE(refined_is_best(v, 130.0));
  EXPECT_FALSE(refined_is_best(v, 130.1)) << "older than 3 intervals";
  v.sigma[2] = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(refined_is_best(v, 100.0));
  v.sigma[2] = 0.1;
  v.converged = false;
  EXPECT_FALSE(refined_is_best(v, 100.0));
}

}  // namespace
}  // namespace scp::daemon::refine

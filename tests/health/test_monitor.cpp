// The health monitor on synthetic windows and score blocks (monitor_run.hpp): quiet on a steady
// plant, `changed` with the parameter and onset after a step, `drift` (once, and no `changed`)
// on a plant drifting from the start, changes that recur in one block, acknowledgements, and bad
// input.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "tests/health/monitor_run.hpp"

namespace scp::health {
namespace {

test::ThetaOfTime steady() {
  return [](double) { return test::paper_theta(); };
}

test::ThetaOfTime step(int parameter, double relative, double at) {
  return [=](double t) {
    Vector6 th = test::paper_theta();
    if (t >= at) th[parameter] *= 1.0 + relative;
    return th;
  };
}

TEST(HealthMonitor, ASteadyPlantRaisesNothingAtTheDefaultDesign) {
  // Two hours at 30 days' design: the expected number of false alarms is 0.003.
  test::RunOptions o;
  o.duration_s = 7200.0;
  const auto r = test::run_monitor(HealthSettings{}, steady(), o);
  EXPECT_TRUE(r.events.empty());
  EXPECT_EQ(r.report.state, State::ok);
  EXPECT_TRUE(r.report.fast.active);
  EXPECT_TRUE(r.report.drift.valid);
  EXPECT_GT(r.report.windows, 600u);
}

TEST(HealthMonitor, FalseAlarmsFollowTheDesignedInterval) {
  // Designed for one false alarm per 30 min of running among the three detectors, with every
  // practical floor off: 6 h should give ~12 (Poisson: 5..21 holds 99 %). Ignoring the windows'
  // overlap would give several times more; the bench measures this over far longer runs.
  HealthSettings s;
  s.false_alarm_days = 30.0 / 1440.0;
  s.min_relative_change = 0.0;
  s.drift_per_hour = 1e-6;
  int alarms = 0;
  for (std::uint64_t seed : {1u, 2u}) {
    test::RunOptions o;
    o.duration_s = 3 * 3600.0;
    o.seed = seed;
    const auto r = test::run_monitor(s, steady(), o);
    alarms += r.changes() + r.drifts();
  }
  EXPECT_GE(alarms, 5);
  EXPECT_LE(alarms, 21);
}

// The change of the first event that names a parameter definitely (ChangePoint::definite).
const ChangePoint* first_name(const std::vector<HealthEvent>& events) {
  for (const auto& e : events)
    if ((e.kind == EventKind::changed || e.kind == EventKind::named) && e.change.definite &&
        e.change.parameter >= 0)
      return &e.change;
  return nullptr;
}

TEST(HealthMonitor, AThermalStepIsChangedWithItsOnsetAndParameter) {
  // λ/Cth +10 %: the alarm may come in the block after the step's, before any block after the
  // onset's to name it from; the name then follows within a block or two.
  const double at = 1803.7;
  test::RunOptions o;
  o.duration_s = 3600.0;
  const auto r = test::run_monitor(HealthSettings{}, step(4, 0.10, at), o);
  ASSERT_EQ(r.changes(), 1);
  ASSERT_EQ(r.drifts(), 0);
  const ChangePoint& c = r.events.front().change;
  EXPECT_EQ(c.detector, Detector::fast);
  EXPECT_TRUE(c.parameter == 4 || (!c.definite && c.candidates[4])) << c.parameter;
  EXPECT_NEAR(c.onset, at, 1.5);
  EXPECT_LT(c.detected_at - at, 3.0);
  const ChangePoint* named = first_name(r.events);
  ASSERT_NE(named, nullptr);
  EXPECT_EQ(named->detector, Detector::fast);
  EXPECT_EQ(named->parameter, 4);
  EXPECT_LT(named->detected_at - at, 3.0);
  EXPECT_NEAR(named->parameters[4].relative, 0.10, 0.01);
  EXPECT_EQ(r.report.change.parameter, 4);
  EXPECT_EQ(r.report.state, State::changed);
}

TEST(HealthMonitor, ADampingStepIsFoundFastAndNamed) {
  // b/m +10 % (the first case): found by the fast detector, which names the mechanical
  // block only as its set of candidates (naming.hpp: on a real plant their linearized responses
  // differ by about the change's second-order term); the first window after the onset names b/m,
  // θ1..θ4 strongly correlated as they are, by the single-parameter GLR of its departure.
  const double at = 2400.3;
  test::RunOptions o;
  o.duration_s = 3000.0;
  for (std::uint64_t seed : {1u, 2u, 3u, 5u}) {
    o.seed = seed;
    const auto r = test::run_monitor(HealthSettings{}, step(0, 0.10, at), o);
    ASSERT_EQ(r.changes(), 1) << seed;
    ASSERT_EQ(r.events.size(), 2u) << seed;
    const ChangePoint& c = r.events.front().change;
    EXPECT_EQ(c.detector, Detector::fast);
    EXPECT_EQ(c.parameter, -1);
    EXPECT_FALSE(c.definite);
    for (int i = 0; i < kParams; ++i) EXPECT_EQ(c.candidates[i], block_of(i) == 0) << i;
    EXPECT_NEAR(c.onset, at, 1.5);
    // The design delay for 10 % of b/m is ~5 blocks here (k capped at 1, h ≈ 9): the synthetic
    // information of θ1 alone is ~3σ per 1 s block.
    EXPECT_LT(c.detected_at - at, 2.0 * r.report.fast.design_delay_s[0] + 1.0);
    const HealthEvent& named = r.events.back();
    EXPECT_EQ(named.kind, EventKind::named);
    EXPECT_EQ(named.change.detector, Detector::sure);
    EXPECT_EQ(named.change.parameter, 0);
    EXPECT_NEAR(named.change.onset, c.onset, 1e-9);
    // One window length after the onset, the next refit at most.
    EXPECT_GE(named.t, c.onset + o.window_s);
    EXPECT_LE(named.t, c.onset + o.window_s + o.chunk_s + 1.0);
    EXPECT_NEAR(named.change.parameters[0].relative, 0.10, 0.02);
    EXPECT_EQ(r.report.change.parameter, 0);
    EXPECT_EQ(r.report.state, State::changed);
  }
}

TEST(HealthMonitor, AChangeNoOneParameterExplainsStaysNamedAsItsSet) {
  // b/m +10 % and a1/m +15 % at once: the window after the onset departs where no one parameter
  // explains it, like a drifting plant's misfit windows (one named a1/m for a b/m drift). It
  // names none, though a1/m explains the departure best by far.
  const double at = 2400.3;
  test::RunOptions o;
  o.duration_s = 3000.0;
  const test::ThetaOfTime two = [at](double t) {
    Vector6 th = test::paper_theta();
    if (t >= at) {
      th[0] *= 1.10;
      th[1] *= 1.15;
    }
    return th;
  };
  for (std::uint64_t seed : {1u, 2u, 3u}) {
    o.seed = seed;
    const auto r = test::run_monitor(HealthSettings{}, two, o);
    ASSERT_EQ(r.changes(), 1) << seed;
    for (const auto& e : r.events) EXPECT_NE(e.kind, EventKind::named) << seed;
    EXPECT_EQ(r.report.change.parameter, -1) << seed;
    EXPECT_TRUE(r.report.change.candidates[0] && r.report.change.candidates[1]) << seed;
  }
}

TEST(HealthMonitor, WindowsTheFitFoundMisfitsNameNothing) {
  // The damping step above, each window after it flagged by the fit's validation (residuals
  // with structure left, as a plant drifting within its windows leaves): found, never named.
  const double at = 2400.3;
  test::RunOptions o;
  o.duration_s = 3000.0;
  o.misfit_from_s = at;
  for (std::uint64_t seed : {1u, 2u}) {
    o.seed = seed;
    const auto r = test::run_monitor(HealthSettings{}, step(0, 0.10, at), o);
    ASSERT_EQ(r.changes(), 1) << seed;
    for (const auto& e : r.events) EXPECT_NE(e.kind, EventKind::named) << seed;
    EXPECT_EQ(r.report.change.parameter, -1) << seed;
  }
}

TEST(HealthMonitor, AHeatingStepIsNamedByTheFastDetector) {
  // R +10 %: T̄ alone tells θ6 from θ5, within a block or two on these linear blocks; no name
  // before that one, and no other event.
  const double at = 1900.6;
  test::RunOptions o;
  o.duration_s = 2400.0;
  const auto r = test::run_monitor(HealthSettings{}, step(5, 1.0 / 1.1 - 1.0, at), o);
  ASSERT_EQ(r.changes(), 1);
  ASSERT_LE(r.events.size(), 2u);
  const ChangePoint* named = first_name(r.events);
  ASSERT_NE(named, nullptr);
  EXPECT_EQ(named->detector, Detector::fast);
  EXPECT_EQ(named->parameter, 5);
  EXPECT_LT(named->detected_at - at, 3.0);
  EXPECT_NEAR(named->parameters[5].relative, 1.0 / 1.1 - 1.0, 0.01);
}

TEST(HealthMonitor, TheSureDetectorAloneFindsAMechanicalStep) {
  // Without residual blocks: the windows alone. b/m +10 % is ~9σ of one window.
  const double at = 2405.0;
  test::RunOptions o;
  o.duration_s = 4200.0;
  o.blocks = false;
  const auto r = test::run_monitor(HealthSettings{}, step(0, 0.10, at), o);
  ASSERT_EQ(r.changes(), 1);
  const ChangePoint& c = r.events.front().change;
  EXPECT_EQ(c.detector, Detector::sure);
  EXPECT_EQ(c.parameter, 0);
  // Confirmed once a window lies after the onset (step or late drift?): one window length and
  // a few refits after the step.
  EXPECT_GT(c.detected_at, at + 300.0);
  EXPECT_LT(c.detected_at - at, 300.0 + 60.0);
  EXPECT_NEAR(c.onset, at, 15.0);
}

TEST(HealthMonitor, APlantDriftingFromTheStartIsDriftNotChanged) {
  // b/m +20 %/h from the baseline on (the drifting plant).
  test::RunOptions o;
  o.duration_s = 1.5 * 3600.0;
  const auto theta = [](double t) {
    Vector6 th = test::paper_theta();
    th[0] *= 1.0 + 0.2 * std::max(t, 0.0) / 3600.0;
    return th;
  };
  const auto r = test::run_monitor(HealthSettings{}, theta, o);
  EXPECT_EQ(r.changes(), 0);
  ASSERT_EQ(r.drifts(), 1);
  EXPECT_EQ(r.report.state, State::drift);
  const ParameterTrend& b = r.report.drift.parameters[0];
  EXPECT_TRUE(b.drifting);
  EXPECT_NEAR(b.relative_per_hour / 0.2, 1.0, 0.5);  // relative to the drifted level
  EXPECT_TRUE(r.report.baseline_deviation.parameters[0].moved);
}

TEST(HealthMonitor, ADriftThatStartsLateIsMostlyDrift) {
  // b/m +20 %/h from 30 min on: the reference (a trend over the last 20 min) lags behind the
  // kink for a while, and the step/ramp shape tests must call most of them drifts (the rate of
  // `changed` is measured in bench/bench_health_calibration.cpp).
  int changes = 0, drifts = 0;
  for (std::uint64_t seed = 1; seed <= 4; ++seed) {
    test::RunOptions o;
    o.duration_s = 1.5 * 3600.0;
    o.seed = seed;
    const auto theta = [](double t) {
      Vector6 th = test::paper_theta();
      th[0] *= 1.0 + 0.2 * std::max(t - 1800.0, 0.0) / 3600.0;
      return th;
    };
    const auto r = test::run_monitor(HealthSettings{}, theta, o);
    changes += r.changes();
    drifts += r.drifts() > 0 ? 1 : 0;
  }
  EXPECT_EQ(drifts, 4);
  EXPECT_LE(changes, 2);
}

// b/m stepping by `relative` at each of `at`.
test::ThetaOfTime staircase(double relative, std::vector<double> at) {
  return [=](double t) {
    Vector6 th = test::paper_theta();
    for (double a : at)
      if (t >= a) th[0] *= 1.0 + relative;
    return th;
  };
}

TEST(HealthMonitor, ChangesThatRecurInOneBlockAreOneDrift) {
  // Three b/m steps 600 s apart, each within reference_span_s (1200 s) of the last alarm: the
  // first is `changed`, the second continues it as one `drift` of the mechanical block since
  // the first onset, the third is counted without an event.
  const double first = 2405.0;
  test::RunOptions o;
  o.duration_s = first + 1800.0;
  const auto r = test::run_monitor(HealthSettings{},
                                   staircase(0.10, {first, first + 600.0, first + 1200.0}), o);
  EXPECT_EQ(r.changes(), 1);
  ASSERT_EQ(r.drifts(), 1);
  EXPECT_EQ(r.report.drift_alarms, 2u);
  EXPECT_EQ(r.report.state, State::drift);
  for (const auto& e : r.events) {
    if (e.kind != EventKind::drift) continue;
    EXPECT_NEAR(e.change.onset, first, 15.0);
    EXPECT_GT(e.t, first + 600.0);
    EXPECT_TRUE(e.change.candidates[0]);
    EXPECT_FALSE(e.change.candidates[4]);
    EXPECT_FALSE(e.change.candidates[5]);
  }
}

void expect_two_separate_changes(const test::RunResult& r) {
  EXPECT_EQ(r.changes(), 2);
  EXPECT_EQ(r.drifts(), 0);
  EXPECT_EQ(r.report.drift_alarms, 0u);
  EXPECT_EQ(r.report.state, State::changed);
}

TEST(HealthMonitor, StepsFartherApartThanTheReferenceSpanAreTwoChanges) {
  const double first = 2405.0;
  test::RunOptions o;
  o.duration_s = first + 2100.0;
  expect_two_separate_changes(
      test::run_monitor(HealthSettings{}, staircase(0.10, {first, first + 1500.0}), o));
}

TEST(HealthMonitor, AStepAfterAnAcknowledgedChangeIsAChangeOfItsOwn) {
  // The same steps 600 s apart as above, the first acknowledged before the second: the user has
  // accepted the actuator as it became, so the second is not the first one going on.
  const double first = 2405.0;
  test::RunOptions o;
  o.duration_s = first + 1200.0;
  o.acknowledge_at_s = first + 300.0;
  expect_two_separate_changes(
      test::run_monitor(HealthSettings{}, staircase(0.10, {first, first + 600.0}), o));
}

TEST(HealthMonitor, AcknowledgeReturnsToOk) {
  HealthMonitor m(HealthSettings{}, test::baseline_window(test::paper_theta(),
                                                          test::window_covariance_300s(), 300, 1));
  m.acknowledge(5.0);
  EXPECT_TRUE(m.take_events().empty());  // nothing latched: nothing to acknowledge
  test::WindowStream s(step(5, -0.2, 0.0), test::window_covariance_300s(), 300, 10, 3);
  m.add_window(s.next());  // the first window against the baseline: θ6 −20 %
  auto events = m.take_events();
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].change.parameter, 5);
  EXPECT_EQ(events[0].change.detector, Detector::sure);
  EXPECT_EQ(m.report().state, State::changed);
  m.acknowledge(400.0);
  events = m.take_events();
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].kind, EventKind::acknowledged);
  EXPECT_EQ(m.report().state, State::ok);
  EXPECT_EQ(m.report().since, 400.0);
}

TEST(HealthMonitor, BadWindowsAreCountedNotUsed) {
  HealthMonitor m(HealthSettings{}, test::baseline_window(test::paper_theta(),
                                                          test::window_covariance_300s(), 300, 1));
  WindowEstimate w =
      test::baseline_window(test::paper_theta(), test::window_covariance_300s(), 300, 2);
  w.t_begin += 300;
  w.t_end += 300;
  WindowEstimate nan = w;
  nan.theta[2] = std::nan("");
  m.add_window(nan);
  WindowEstimate backwards = w;
  backwards.t_end = backwards.t_begin;
  m.add_window(backwards);
  m.add_window(w);
  m.add_window(w);  // not after the previous one
  EXPECT_EQ(m.report().windows, 4u);
  EXPECT_EQ(m.report().windows_rejected, 3u);
  EXPECT_TRUE(m.take_events().empty());
}

TEST(HealthSettings, ValidationNamesTheKey) {
  EXPECT_EQ(validate(HealthSettings{}), "");
  HealthSettings s;
  s.false_alarm_days = 0.0;
  EXPECT_NE(validate(s).find("health.false_alarm_days"), std::string::npos);
  s = HealthSettings{};
  s.trend_min_span_s = 7200.0;
  EXPECT_NE(validate(s).find("health.trend_min_span_s"), std::string::npos);
  s = HealthSettings{};
  s.reference_span_s = 7200.0;
  EXPECT_NE(validate(s).find("health.reference_span_s"), std::string::npos);
  s = HealthSettings{};
  s.block_s = std::nan("");
  EXPECT_NE(validate(s).find("health.block_s"), std::string::npos);
}

}  // namespace
}  // namespace scp::health

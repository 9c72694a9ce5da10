// The health detectors measured on simulated streams (docs/health.md): the false-alarm rate of
// each against its design, and detection delays against the ARL formula. Not a timing benchmark:
// every figure is a count or a ratio, the same on any machine for the same seeds.
//
//   bench_health_calibration [--quick] [cusum|scan|bank|null|steps|drift ...]
//
// 1. CUSUM: run lengths under no change and after a shift, against Siegmund's approximation.
// 2. Repeated tests on overlapping windows: alarms of a moving-window χ²_p process against the
//    crossing-rate formula of health/scan_threshold.hpp.
// 3. The monitor on a steady plant (synthetic windows and score blocks, tests/health/), with a
//    short designed interval so that false alarms can be counted, per detector; and at the
//    default 30 days.
// 4. The monitor after steps of 10 % (b/m, λ/Cth, 1/(R·Cth), k/m) at random times: detection
//    rate, delay (median, p95), the parameter named first; and on a plant drifting at b/m
//    +20 %/h from the start or from 30 min.

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "health/cusum.hpp"
#include "health/scan_threshold.hpp"
#include "tests/health/monitor_run.hpp"
#include "tests/health/moving_window.hpp"

namespace {

using namespace scp::health;

void cusum_section(bool quick) {
  std::printf("## CUSUM run lengths (two-sided, N(mu,1) blocks)\n");
  std::printf(
      "| k | design ARL0 | h | measured ARL0 | ratio | shift | formula delay | measured delay |\n");
  std::printf("|---|---|---|---|---|---|---|---|\n");
  std::mt19937_64 rng(1);
  std::normal_distribution<double> n;
  for (double k : {0.25, 0.5, 1.0, 2.0}) {
    for (double arl0 : {1e3, quick ? 1e4 : 1e5}) {
      // k = 2 beyond the monitor's cap, to show why it is capped at 1.
      const CusumDesign d = design_cusum(2.0 * k, arl0, 0.0, k);
      TwoSidedCusum c(d);
      const int runs = arl0 > 5e4 ? 300 : 2000;
      double total = 0.0, delay = 0.0;
      for (int r = 0; r < runs; ++r) {
        c.reset();
        for (long i = 1;; ++i)
          if (c.update(n(rng), static_cast<double>(i))) {
            total += static_cast<double>(i);
            break;
          }
        c.reset();
        for (long i = 1;; ++i)
          if (c.update(2.0 * k + n(rng), static_cast<double>(i))) {
            delay += static_cast<double>(i);
            break;
          }
      }
      std::printf("| %.2f | %.0f | %.3f | %.0f (%d runs) | %.3f | %.1f | %.2f | %.2f |\n", k, arl0,
                  d.h, total / runs, runs, total / runs / arl0, 2.0 * k, cusum_delay(d, 2.0 * k),
                  delay / runs);
    }
  }
}

void scan_section(bool quick) {
  std::printf(
      "\n## Repeated tests on overlapping windows (30 chunks per window, tested every chunk)\n");
  std::printf(
      "| dof | design rate per test | b | alarms | measured / design |\n|---|---|---|---|---|\n");
  for (int dof : {1, 2, 4}) {
    for (double rate : {1e-4, 1e-5, quick ? 1e-5 : 1e-6}) {
      const double b = chi_square_scan_threshold(rate, dof, 1.0 / 30.0, 1.0);
      const long steps = static_cast<long>(300.0 / rate);
      const double measured = test::moving_window_alarm_rate(dof, 30, b, steps, 5 + dof);
      std::printf("| %d | %.0e | %.2f | %.0f | %.3f |\n", dof, rate, b, measured * steps,
                  measured / rate);
      if (quick && rate < 1e-4) break;
    }
  }
}

// The fast detector's six CUSUMs as the monitor designs them, on synthetic score blocks against
// an exact reference (bias 0) and against one redrawn from N(0, C_window) every 10 blocks, the
// design averaging over a constant bias of that variance: which part of the monitor's false
// alarms the CUSUMs themselves account for.
void bank_section(bool quick) {
  std::printf("\n## The fast detector's CUSUMs alone (6 parameters, one alarm per 3 h designed)\n");
  const Matrix6 cw = test::window_covariance_300s();
  const Matrix6 info = (cw * 300.0).inverse();
  const Vector6 theta = test::paper_theta();
  const double hours = quick ? 100.0 : 2000.0;
  for (bool biased : {false, true}) {
    const Matrix6 spread = info * cw * info;
    std::array<TwoSidedCusum, kParams> cusums;
    for (int i = 0; i < kParams; ++i)
      cusums[i].set_design(design_cusum(0.1 * theta[i] * std::sqrt(info(i, i)),
                                        kParams * 3.0 * 3600.0,
                                        biased ? spread(i, i) / info(i, i) : 0.0));
    test::ScoreStream scores(info, 7);
    const Matrix6 l = cw.llt().matrixL();
    std::mt19937_64 rng(3);
    std::normal_distribution<double> n;
    Vector6 reference = theta;
    long alarms = 0;
    for (long b = 0; b < static_cast<long>(hours * 3600.0); ++b) {
      if (biased && b % 10 == 0) {
        Vector6 e;
        for (int i = 0; i < kParams; ++i) e[i] = n(rng);
        reference = theta + l * e;
      }
      const Vector6 z = scores.block(b, b + 1, theta, reference).z();
      bool alarm = false;
      for (int i = 0; i < kParams; ++i) alarm = cusums[i].update(z[i], b) || alarm;
      if (!alarm) continue;
      ++alarms;
      for (auto& c : cusums) c.reset();
    }
    std::printf("%s: %ld alarms in %.0f h, designed %.1f\n",
                biased ? "reference redrawn every 10 blocks" : "exact reference", alarms, hours,
                hours / 3.0);
  }
}

test::ThetaOfTime steady() {
  return [](double) { return test::paper_theta(); };
}

void null_section(bool quick) {
  std::printf("\n## The monitor on a steady plant\n");
  HealthSettings s;
  s.false_alarm_days = 1.0 / 24.0;  // one false alarm per hour of running, all detectors
  s.min_relative_change = 0.0;
  s.drift_per_hour = 1e-6;
  const int runs = quick ? 4 : 40;
  int fast = 0, sure = 0, drift = 0;
  double hours = 0.0;
  for (int seed = 1; seed <= runs; ++seed) {
    test::RunOptions o;
    o.duration_s = 3.0 * 3600.0;
    o.seed = static_cast<std::uint64_t>(seed);
    const auto r = test::run_monitor(s, steady(), o);
    hours += o.duration_s / 3600.0;
    for (const auto& e : r.events) {
      if (e.kind == EventKind::drift) ++drift;
      if (e.kind == EventKind::changed) ++(e.change.detector == Detector::fast ? fast : sure);
    }
  }
  const double expected = hours / 24.0 / s.false_alarm_days / 3.0;
  std::printf(
      "designed 1 per hour (floors off), %.0f simulated hours: expected %.1f per "
      "detector; fast %d, sure %d, drift %d\n",
      hours, expected, fast, sure, drift);
  int alarms = 0;
  double default_hours = 0.0;
  for (int seed = 1; seed <= (quick ? 2 : 5); ++seed) {
    test::RunOptions o;
    o.duration_s = 2.0 * 3600.0;
    o.seed = static_cast<std::uint64_t>(100 + seed);
    const auto r = test::run_monitor(HealthSettings{}, steady(), o);
    alarms += r.changes() + r.drifts();
    default_hours += o.duration_s / 3600.0;
  }
  std::printf("default design (30 days), %.0f simulated hours: %d alarms (expected %.3f)\n",
              default_hours, alarms, default_hours / (30.0 * 24.0));
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(std::min<double>(v.size() - 1, p * (v.size() - 1) + 0.5))];
}

void step_section(bool quick) {
  std::printf("\n## The monitor after a step at a random time (synthetic streams)\n");
  std::printf(
      "| step | seeds | detected | named right first | delay median s | delay p95 s | "
      "onset error median s | other alarms |\n|---|---|---|---|---|---|---|---|\n");
  struct Case {
    const char* name;
    int parameter;
    double relative;
  } cases[] = {{"b/m +10 %", 0, 0.10},
               {"l/Cth -10 %", 4, -0.10},
               {"1/(R Cth) (R +10 %)", 5, 1.0 / 1.1 - 1.0},
               {"k/m -10 %", 2, -0.10}};
  const int seeds = quick ? 5 : 20;
  for (const auto& c : cases) {
    std::vector<double> delays, onset_errors;
    int detected = 0, named = 0, other = 0;
    std::mt19937_64 rng(42);
    std::uniform_real_distribution<double> when(1800.0, 2700.0);
    for (int seed = 1; seed <= seeds; ++seed) {
      const double at = when(rng);
      test::RunOptions o;
      o.duration_s = at + 600.0;
      o.seed = static_cast<std::uint64_t>(seed);
      const auto theta = [&](double t) {
        Vector6 th = test::paper_theta();
        if (t >= at) th[c.parameter] *= 1.0 + c.relative;
        return th;
      };
      const auto r = test::run_monitor(HealthSettings{}, theta, o);
      bool first = true, name_seen = false;
      for (const auto& e : r.events) {
        // The first definite name: the change's own, or the `named` event that follows it.
        if (e.kind == EventKind::named && !first && !name_seen) {
          name_seen = true;
          named += e.change.parameter == c.parameter ? 1 : 0;
          continue;
        }
        if (e.kind != EventKind::changed || e.change.detected_at < at || !first) {
          ++other;
          continue;
        }
        first = false;
        ++detected;
        if (e.change.definite) {
          name_seen = true;
          named += e.change.parameter == c.parameter ? 1 : 0;
        }
        delays.push_back(e.change.detected_at - at);
        onset_errors.push_back(std::abs(e.change.onset - at));
      }
    }
    std::printf("| %s | %d | %d | %d | %.1f | %.1f | %.1f | %d |\n", c.name, seeds, detected, named,
                percentile(delays, 0.5), percentile(delays, 0.95), percentile(onset_errors, 0.5),
                other);
  }
}

void drift_section(bool quick) {
  std::printf("\n## A plant drifting at b/m +20 %%/h\n");
  const int seeds = quick ? 3 : 10;
  for (double start : {0.0, 1800.0}) {
    int changed = 0, with_drift = 0;
    std::vector<double> raised;
    for (int seed = 1; seed <= seeds; ++seed) {
      test::RunOptions o;
      o.duration_s = 3.0 * 3600.0;
      o.seed = static_cast<std::uint64_t>(seed);
      const auto theta = [start](double t) {
        Vector6 th = test::paper_theta();
        th[0] *= 1.0 + 0.2 * std::max(t - start, 0.0) / 3600.0;
        return th;
      };
      const auto r = test::run_monitor(HealthSettings{}, theta, o);
      changed += r.changes();
      for (const auto& e : r.events)
        if (e.kind == EventKind::drift) {
          ++with_drift;
          raised.push_back(e.t - start);
          break;
        }
    }
    std::printf(
        "from %.0f s, %d seeds of 3 h: drift raised in %d (median %.0f s after it "
        "began), changed %d times\n",
        start, seeds, with_drift, percentile(raised, 0.5), changed);
  }
}

}  // namespace

int main(int argc, char** argv) {
  bool quick = false;
  std::vector<std::string> only;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--quick") == 0) {
      quick = true;
    } else {
      only.emplace_back(argv[i]);
    }
  }
  const struct {
    const char* name;
    void (*run)(bool);
  } sections[] = {{"cusum", cusum_section}, {"scan", scan_section},  {"bank", bank_section},
                  {"null", null_section},   {"steps", step_section}, {"drift", drift_section}};
  for (const auto& section : sections)
    if (only.empty() || std::find(only.begin(), only.end(), section.name) != only.end())
      section.run(quick);
  return 0;
}

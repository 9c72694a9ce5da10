// The model validation's false-alarm rate and power (refine/validation.hpp, docs/validation.md):
// real fits (refine::fit) of windows made by a second simulator (tests/refine/deviation_record.hpp:
// RK4 on the whole state, not the fit's integrator), clean and with each deviation of a real
// bench, at the N1 and N3 sensor noise, over seeds; per cell the verdict counts per block, the
// test each verdict named, how often each test failed and the median estimated size of each
// targeted term.
//
//   build/bench/validation_sweep [--seconds 300] [--warmup 0] [--seeds 20] [--first-seed 1]
//                                [--cells clean,zero_50um,...] [--noise n1,n3] [--per-seed]
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <string>
#include <vector>

#include "refine/fit.hpp"
#include "refine/validate_fit.hpp"
#include "tests/refine/deviation_record.hpp"
#include "tests/refine/record.hpp"

namespace {

using namespace scp::refine;

struct Cell {
  const char* name;
  test::Deviations deviations;
  ValidationTest expected;  // the test that names this deviation (kNone: clean)
};

std::vector<Cell> all_cells() {
  std::vector<Cell> c;
  c.push_back({"clean", {}, ValidationTest::kNone});
  c.push_back({"zero_50um", {.displacement_zero = 50e-6}, ValidationTest::kDisplacementZero});
  c.push_back({"zero_1mm", {.displacement_zero = 1e-3}, ValidationTest::kDisplacementZero});
  c.push_back({"ambient_off_1", {.ambient_offset = 1.0}, ValidationTest::kAmbientOffset});
  c.push_back({"ambient_off_2", {.ambient_offset = -2.0}, ValidationTest::kAmbientOffset});
  c.push_back(
      {"ambient_drift_2_per_h", {.ambient_drift = 2.0 / 3600.0}, ValidationTest::kAmbientDrift});
  c.push_back({"sensor_lag_0.3s", {.sensor_lag = 0.3}, ValidationTest::kSensorLag});
  c.push_back({"r_tempco_0.004", {.resistance_tempco = 0.004}, ValidationTest::kResistanceTempco});
  c.push_back({"stiffness_-0.3%", {.stiffness_tempco = 0.003}, ValidationTest::kStiffnessTempco});
  c.push_back({"cooling_+0.5%", {.cooling_tempco = 0.005}, ValidationTest::kCoolingTempco});
  return c;
}

struct NoiseLevel {
  const char* name;
  double x, tbar;
};

std::vector<std::string> split(const char* s) {
  std::vector<std::string> out;
  std::string cur;
  for (const char* p = s; *p; ++p) {
    if (*p == ',') {
      out.push_back(cur);
      cur.clear();
    } else {
      cur += *p;
    }
  }
  if (!cur.empty()) out.push_back(cur);
  return out;
}

struct Tally {
  int fits = 0, converged = 0;
  std::map<std::string, int> mech_verdicts, therm_verdicts, named_mech, named_therm;
  std::array<int, kValidationTests> failed{};
  std::array<int, kValidationTests> below_5_percent{};  // p < 0.05: calibration on clean data
  std::array<std::vector<double>, kValidationTests> effects;
  int adequate_both = 0;
  int named_expected = 0;
};

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

void print_map(const char* label, const std::map<std::string, int>& m) {
  std::printf("  %s:", label);
  for (const auto& [k, n] : m) std::printf(" %s %d", k.c_str(), n);
  std::printf("\n");
}

void report(const Cell& cell, const NoiseLevel& noise, const Tally& t) {
  std::printf("%s %s: fits %d, converged %d, adequate (both blocks) %d", cell.name, noise.name,
              t.fits, t.converged, t.adequate_both);
  if (cell.expected != ValidationTest::kNone)
    std::printf(", named %s %d", test_name(cell.expected), t.named_expected);
  std::printf("\n");
  print_map("mechanical", t.mech_verdicts);
  print_map("  named", t.named_mech);
  print_map("thermal", t.therm_verdicts);
  print_map("  named", t.named_therm);
  std::printf("  failed:");
  for (int i = 0; i < kValidationTests; ++i)
    if (t.failed[i] > 0)
      std::printf(" %s %d", test_name(static_cast<ValidationTest>(i)), t.failed[i]);
  std::printf("\n  p < 0.05:");
  for (int i = 0; i < kValidationTests; ++i)
    std::printf(" %s %d", test_name(static_cast<ValidationTest>(i)), t.below_5_percent[i]);
  std::printf("\n  median effect:");
  for (int i = 0; i < kValidationTests; ++i)
    if (!t.effects[i].empty())
      std::printf(" %s %.3g", test_name(static_cast<ValidationTest>(i)), median(t.effects[i]));
  std::printf("\n");
  std::fflush(stdout);
}

struct Options {
  double seconds = 300.0;
  double warmup = 0.0;  // s simulated before the window (a refit of a running experiment)
  int seeds = 20, first_seed = 1;
  bool per_seed = false;
  std::vector<std::string> cells, noise{"n1", "n3"};
};

bool parse(int argc, char** argv, Options& o) {
  for (int i = 1; i < argc; ++i) {
    const bool has_value = i + 1 < argc;
    if (!std::strcmp(argv[i], "--seconds") && has_value) {
      o.seconds = std::atof(argv[++i]);
    } else if (!std::strcmp(argv[i], "--warmup") && has_value) {
      o.warmup = std::atof(argv[++i]);
    } else if (!std::strcmp(argv[i], "--seeds") && has_value) {
      o.seeds = std::atoi(argv[++i]);
    } else if (!std::strcmp(argv[i], "--first-seed") && has_value) {
      o.first_seed = std::atoi(argv[++i]);
    } else if (!std::strcmp(argv[i], "--cells") && has_value) {
      o.cells = split(argv[++i]);
    } else if (!std::strcmp(argv[i], "--noise") && has_value) {
      o.noise = split(argv[++i]);
    } else if (!std::strcmp(argv[i], "--per-seed")) {
      o.per_seed = true;
    } else {
      return false;
    }
  }
  return o.seconds > 0.0 && o.warmup >= 0.0 && o.seeds > 0;
}

void print_seed(int seed, const FitResult& r, const ValidationReport& v) {
  std::printf(
      "  seed %d: %s; x %s (%s) fit %.2f%% ratio %.2f; T %s (%s) fit %.2f%% ratio %.2f; θ̂1 %.4g\n",
      seed, r.converged ? "converged" : r.message, verdict_name(v.mechanical.verdict),
      test_name(v.mechanical.decisive), v.mechanical.fit_percent, v.mechanical.noise_ratio,
      verdict_name(v.thermal.verdict), test_name(v.thermal.decisive), v.thermal.fit_percent,
      v.thermal.noise_ratio, r.theta[0]);
  for (int i = 0; i < kValidationTests; ++i) {
    const TestOutcome& o = v.tests[i];
    if (!o.performed) continue;
    std::printf("    %-18s F/Q %10.4g dof %d,%d p %.3g%s effect %.4g ar1 %.3f explained %.3f\n",
                test_name(static_cast<ValidationTest>(i)), o.statistic, o.dof1, o.dof2, o.p_value,
                o.failed ? " FAIL" : "", o.effect, o.ar1, o.explained);
  }
}

void count(const Cell& cell, const FitResult& r, const ValidationReport& v, Tally& t) {
  ++t.fits;
  t.converged += r.converged ? 1 : 0;
  ++t.mech_verdicts[verdict_name(v.mechanical.verdict)];
  ++t.therm_verdicts[verdict_name(v.thermal.verdict)];
  ++t.named_mech[test_name(v.mechanical.decisive)];
  ++t.named_therm[test_name(v.thermal.decisive)];
  if (v.mechanical.verdict == Verdict::kAdequate && v.thermal.verdict == Verdict::kAdequate)
    ++t.adequate_both;
  if (cell.expected != ValidationTest::kNone &&
      v.block(block_of(cell.expected)).decisive == cell.expected)
    ++t.named_expected;
  for (int i = 0; i < kValidationTests; ++i) {
    const TestOutcome& o = v.tests[i];
    if (o.failed) ++t.failed[i];
    if (o.performed && o.p_value < 0.05) ++t.below_5_percent[i];
    if (o.performed && std::isfinite(o.effect)) t.effects[i].push_back(o.effect);
  }
}

// One cell at one noise level: the seeds' fits, each validated with the noise declared.
Tally run_cell(const Cell& cell, const std::vector<WindowSample>& clean, const NoiseLevel& noise,
               const Options& o) {
  Vector6 start = test::theta_of(test::paper_actuator());
  start.head<4>() *= 0.17;  // the paper law's biased estimate under noise
  Tally t;
  for (int seed = o.first_seed; seed < o.first_seed + o.seeds; ++seed) {
    const auto w = test::with_noise(
        clean, {.x = noise.x, .tbar = noise.tbar, .seed = static_cast<unsigned>(seed)});
    const FitResult r = fit(w, start);
    ValidationSettings vs;
    vs.declared_noise = Vector2(noise.x, noise.tbar);
    const ValidationReport v = validate_fit(w, r, vs);
    count(cell, r, v, t);
    if (o.per_seed) print_seed(seed, r, v);
  }
  return t;
}

bool wanted(const std::vector<std::string>& list, const char* name) {
  return list.empty() || std::find(list.begin(), list.end(), name) != list.end();
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  if (!parse(argc, argv, o)) {
    std::fprintf(stderr,
                 "usage: %s [--seconds S] [--warmup S] [--seeds N] [--first-seed K] [--cells a,b] "
                 "[--noise n1,n3] [--per-seed]\n",
                 argv[0]);
    return 2;
  }
  const std::vector<NoiseLevel> levels{{"n1", test::kN1.x, test::kN1.tbar},
                                       {"n3", test::kN3.x, test::kN3.tbar}};
  std::printf("validation sweep: %.0f s windows at 1 kHz after %.0f s, seeds %d..%d\n", o.seconds,
              o.warmup, o.first_seed, o.first_seed + o.seeds - 1);
  for (const Cell& cell : all_cells()) {
    if (!wanted(o.cells, cell.name)) continue;
    auto clean = test::deviation_record(test::paper_actuator(), o.warmup + o.seconds, 1e-3,
                                        test::paper_voltage(), cell.deviations);
    clean.erase(clean.begin(), clean.begin() + static_cast<long>(std::llround(o.warmup / 1e-3)));
    for (const NoiseLevel& noise : levels)
      if (wanted(o.noise, noise.name)) report(cell, noise, run_cell(cell, clean, noise, o));
  }
  return 0;
}

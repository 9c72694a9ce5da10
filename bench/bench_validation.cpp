// What the model validation (refine/validation.hpp) costs the fit's final pass: the validator fed
// 300 s at 1 kHz (the window), per sample and as a ratio to one cost-only residual pass
// over the same window (the cheapest pass the fit makes; the follow-up's 300 s refit target is
// 100 ms), and finish()'s tests on the block means.
#include <benchmark/benchmark.h>

#include <chrono>
#include <vector>

#include "refine/model_simulator.hpp"
#include "refine/residual_pass.hpp"
#include "refine/validation.hpp"
#include "tests/refine/record.hpp"

namespace {

using namespace scp::refine;

// The paper's experiment with N1 noise, 300 s.
const std::vector<WindowSample>& window() {
  return test::cached_paper_record_n1(300.0, 7);
}

const Vector6& truth() {
  return test::paper_theta();
}

const std::vector<ModelState>& model() {
  static const auto states = [] {
    std::vector<ModelState> s(window().size());
    simulate(window(), truth(), InitialState::Zero(), s);
    return s;
  }();
  return states;
}

ValidationSettings settings() {
  ValidationSettings s;
  s.mechanical_time_constant_s = 0.7;
  s.thermal_time_constant_s = 17.0;
  s.declared_noise = Vector2(test::kN1.x, test::kN1.tbar);
  s.jacobian_columns = kParams;
  return s;
}

// Feeds the whole window; the sensitivities are stand-ins of the right length (their values do
// not change the work).
ResidualValidator fed_validator() {
  ResidualValidator v(truth(), settings());
  const auto& w = window();
  const auto& m = model();
  ParamVector jx = ParamVector::LinSpaced(1.0, 9.0), jt = ParamVector::LinSpaced(2.0, 3.0);
  for (std::size_t k = 0; k < w.size(); ++k) {
    jx[0] = m[k].x;
    jt[4] = m[k].tbar;
    ValidationSample s;
    s.t = w[k].t;
    s.x = w[k].x;
    s.x_model = m[k].x;
    s.tbar = w[k].tbar;
    s.tbar_model = m[k].tbar;
    s.thermal_input = w[k].voltage * w[k].voltage;
    s.mechanical_input = m[k].tbar;
    s.jacobian_x = {jx.data(), kParams};
    s.jacobian_tbar = {jt.data(), kParams};
    v.add(s);
  }
  return v;
}

void BM_ValidatorFeed300s(benchmark::State& state) {
  model();
  for (auto _ : state) benchmark::DoNotOptimize(fed_validator());
  state.counters["ns_per_sample"] =
      benchmark::Counter(static_cast<double>(window().size()) * state.iterations(),
                         benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_ValidatorFeed300s)->Unit(benchmark::kMillisecond);

void BM_ValidatorFinish300s(benchmark::State& state) {
  const ResidualValidator v = fed_validator();
  for (auto _ : state) benchmark::DoNotOptimize(v.finish());
}
BENCHMARK(BM_ValidatorFinish300s)->Unit(benchmark::kMillisecond);

// Both in one process, alternating: the validator's feed over a cost-only pass (ratio).
void BM_FeedOverCostPass(benchmark::State& state) {
  model();
  const ParamVector p = param_vector(truth(), InitialState::Zero());
  PassSettings ps;
  ps.weight = {1e14, 1e6};
  ps.jacobian = false;
  using clock = std::chrono::steady_clock;
  clock::duration pass{}, feed{};
  for (auto _ : state) {
    const auto t0 = clock::now();
    benchmark::DoNotOptimize(residual_pass(window(), p, ps));
    const auto t1 = clock::now();
    benchmark::DoNotOptimize(fed_validator());
    const auto t2 = clock::now();
    pass += t1 - t0;
    feed += t2 - t1;
  }
  state.counters["feed_over_pass"] =
      std::chrono::duration<double>(feed) / std::chrono::duration<double>(pass);
}
BENCHMARK(BM_FeedOverCostPass)->Unit(benchmark::kMillisecond)->Iterations(5);

}  // namespace

BENCHMARK_MAIN();

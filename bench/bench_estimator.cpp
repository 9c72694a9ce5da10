// ns per Estimator::update on realistic data (the paper's experiment, precomputed so that the
// plant integration is not timed), with a plain 6×6 matrix-vector product as an in-process
// baseline: read the result as a ratio, which travels between machines better than ns.
#include <benchmark/benchmark.h>

#include <Eigen/Core>
#include <cmath>
#include <numbers>
#include <vector>

#include "estimator/estimator.hpp"

namespace {

using scp::estimator::Estimator;
using scp::estimator::EstimatorConfig;
using scp::estimator::Measurement;

// 20 s of the paper's experiment at 1 kHz: slowly varying data with the right magnitudes. A
// quasi-static plant is enough here; accuracy is the tests' job.
std::vector<Measurement> make_data() {
  std::vector<Measurement> data;
  double tbar = 0.0, x = 0.0;
  const double h = 1e-3;
  for (int k = 0; k < 20000; ++k) {
    const double t = k * h;
    const double w1 = 2 * std::numbers::pi * 0.006, w2 = 2 * std::numbers::pi * 0.1;
    const double v = 1.6 + 0.4 * (std::sin(w1 * t - std::numbers::pi / 2) + std::sin(w1 * t) +
                                  std::sin(w2 * t) + std::sin(w2 * t - std::numbers::pi / 2));
    tbar += h * (-0.0594059 * tbar + 1.1001100 * v * v);
    const double x_new = -0.01 * tbar / 181.3;
    data.push_back(
        Measurement{.t = t, .x = x_new, .xdot = (x_new - x) / h, .tbar = tbar, .voltage = v});
    x = x_new;
  }
  return data;
}

void BM_EstimatorUpdate(benchmark::State& state) {
  static const std::vector<Measurement> data = make_data();
  EstimatorConfig config;
  config.scale << 1e3, 1.0, 2e3, 0.1, 0.06, 1.0;
  Estimator est(config);
  std::size_t i = 0;
  double t_offset = 0.0;
  for (auto _ : state) {
    Measurement m = data[i];
    m.t += t_offset;
    benchmark::DoNotOptimize(est.update(m));
    if (++i == data.size()) {  // continue in time so that every update is a full one
      i = 0;
      t_offset += data.size() * 1e-3;
    }
  }
  benchmark::DoNotOptimize(est.estimate().theta_hat);
}
BENCHMARK(BM_EstimatorUpdate);

void BM_MatVec6x6(benchmark::State& state) {
  Eigen::Matrix<double, 6, 6> a = Eigen::Matrix<double, 6, 6>::Random();
  Eigen::Matrix<double, 6, 1> x = Eigen::Matrix<double, 6, 1>::Random();
  for (auto _ : state) {
    benchmark::DoNotOptimize(a);
    benchmark::DoNotOptimize(x);
    Eigen::Matrix<double, 6, 1> y = a * x;
    benchmark::DoNotOptimize(y);
  }
}
BENCHMARK(BM_MatVec6x6);

}  // namespace

// ns per Estimator::update on realistic data (the paper's experiment, precomputed so that the
// plant integration is not timed), the pieces of an update, with a plain 6×6 matrix-vector product
// as an in-process baseline: read the result as a ratio, which travels between machines better than
// ns.
#include <benchmark/benchmark.h>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <cmath>
#include <numbers>
#include <vector>

#include "estimator/estimator.hpp"
#include "estimator/held_lag.hpp"
#include "estimator/small_ldlt.hpp"
#include "tests/estimator/test_plant.hpp"

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

// 200 s of the paper's experiment at 1 kHz from the reference plant of the estimator tests
// (Table I, RK4, the paper's voltage held over each period): what the batch run feeds.
std::vector<Measurement> make_paper_data() {
  std::vector<Measurement> data;
  scp::estimator::test::Plant plant;
  const double h = 1e-3;
  for (int k = 0; k < 200000; ++k) {
    const double t = k * h;
    const double v = scp::estimator::test::paper_voltage(t);
    plant.advance(h, v, 20);
    data.push_back(Measurement{
        .t = t + h, .x = plant.x, .xdot = plant.xdot, .tbar = plant.tbar, .voltage = v});
  }
  return data;
}

void run_updates(benchmark::State& state, const std::vector<Measurement>& data,
                 const EstimatorConfig& config) {
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

// The paper's experiment with config/paper.yaml's estimator (unscaled θ, p_max = 1e20).
void BM_EstimatorUpdate(benchmark::State& state) {
  static const std::vector<Measurement> data = make_paper_data();
  EstimatorConfig config;
  config.p_max = 1e20;
  run_updates(state, data, config);
}
BENCHMARK(BM_EstimatorUpdate);

// The same data with config/sim.yaml's scaled estimator (the daemon's default).
void BM_EstimatorUpdateScaled(benchmark::State& state) {
  static const std::vector<Measurement> data = make_paper_data();
  EstimatorConfig config;
  config.scale << 1000, 1, 1000, 0.1, 0.1, 1;
  config.p_max = 1e10;
  run_updates(state, data, config);
}
BENCHMARK(BM_EstimatorUpdateScaled);

// A quasi-static plant (x ∝ T̄): two mechanical columns are collinear, so R's weakest direction
// sits on the floor and the eigen-decomposition (and its lift) runs every step: the slow path.
void BM_EstimatorUpdateUnexcited(benchmark::State& state) {
  static const std::vector<Measurement> data = make_data();
  EstimatorConfig config;
  config.scale << 1e3, 1.0, 2e3, 0.1, 0.06, 1.0;
  run_updates(state, data, config);
}
BENCHMARK(BM_EstimatorUpdateUnexcited);

// Where an update's time goes: the pieces of BlockRls<4>::step on an SPD 4×4 like R, one by one
// (fixed-size Eigen, as in the estimator).
Eigen::Matrix4d spd4() {
  const Eigen::Matrix4d a = Eigen::Matrix4d::Random();
  return a * a.transpose() + 1e-3 * Eigen::Matrix4d::Identity();
}

void BM_Ldlt4Solve(benchmark::State& state) {  // the step: (R + wᵀw)⁻¹ wᵀ ε
  Eigen::Matrix4d r = spd4();
  Eigen::Vector4d b = Eigen::Vector4d::Random();
  for (auto _ : state) {
    benchmark::DoNotOptimize(r);
    benchmark::DoNotOptimize(b);
    Eigen::Vector4d x = Eigen::LDLT<Eigen::Matrix4d>(r).solve(b);
    benchmark::DoNotOptimize(x);
  }
}
BENCHMARK(BM_Ldlt4Solve);

void BM_SmallLdlt4Solve(benchmark::State& state) {  // the same, written out (small_ldlt.hpp)
  Eigen::Matrix4d r = spd4();
  Eigen::Vector4d b = Eigen::Vector4d::Random();
  for (auto _ : state) {
    benchmark::DoNotOptimize(r);
    benchmark::DoNotOptimize(b);
    Eigen::Vector4d x = scp::estimator::small_ldlt_solve<4>(r, b);
    benchmark::DoNotOptimize(x);
  }
}
BENCHMARK(BM_SmallLdlt4Solve);

void BM_Ldlt4Inverse(benchmark::State& state) {  // σ: the diagonal of P = R⁻¹
  Eigen::Matrix4d r = spd4();
  for (auto _ : state) {
    benchmark::DoNotOptimize(r);
    Eigen::Matrix4d p = Eigen::LDLT<Eigen::Matrix4d>(r).solve(Eigen::Matrix4d::Identity());
    benchmark::DoNotOptimize(p);
  }
}
BENCHMARK(BM_Ldlt4Inverse);

void BM_Eigenvalues4(benchmark::State& state) {  // λ_min(R): p_max_eig, excitation, the lift
  Eigen::Matrix4d r = spd4();
  for (auto _ : state) {
    benchmark::DoNotOptimize(r);
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> es(r, Eigen::EigenvaluesOnly);
    double l = es.eigenvalues()(0);
    benchmark::DoNotOptimize(l);
  }
}
BENCHMARK(BM_Eigenvalues4);

void BM_Eigenvalues2(benchmark::State& state) {
  Eigen::Matrix2d r = spd4().topLeftCorner<2, 2>();
  for (auto _ : state) {
    benchmark::DoNotOptimize(r);
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(r, Eigen::EigenvaluesOnly);
    double l = es.eigenvalues()(0);
    benchmark::DoNotOptimize(l);
  }
}
BENCHMARK(BM_Eigenvalues2);

// The per-step filter coefficients: the hold coefficients every column uses, and the held lag's
// weights T̄'s columns use under a held voltage (the voltage switching at the sample, as a DAC
// clocked with the loop does; h varies in its last bits as it does on a float time base).
void BM_HoldCoefficients(benchmark::State& state) {
  double h = 1e-3;
  for (auto _ : state) {
    benchmark::DoNotOptimize(h);
    const auto c = scp::estimator::HoldCoefficients::make(3.0, h);
    benchmark::DoNotOptimize(c);
    h = std::nextafter(h, 1.0);
  }
}
BENCHMARK(BM_HoldCoefficients);

void BM_HeldLagWeights(benchmark::State& state) {
  const auto hold = scp::estimator::HoldCoefficients::make(3.0, 1e-3);
  double a = 0.0594;
  for (auto _ : state) {
    benchmark::DoNotOptimize(a);
    const auto w = scp::estimator::HeldLagWeights::make(hold, 3.0, a, 2.5, 2.6, 0.0);
    benchmark::DoNotOptimize(w);
    a = std::nextafter(a, 1.0);
  }
}
BENCHMARK(BM_HeldLagWeights);

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

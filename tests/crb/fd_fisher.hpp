#pragma once
// An independent Cramér–Rao bound for the tests of scp-crb: the Fisher information JᵀJ of the
// samples x and T̄ (each divided by its noise sd) with J by central finite differences of
// drivers/sim's RK4 plant, not of refine/'s exact discretization, over θ and the initial state
// (x, ẋ, T̄). The voltage of each sample is held over the interval before it, as a DAC holds it.

#include <Eigen/Dense>
#include <array>
#include <span>
#include <vector>

#include "drivers/sim/plant.hpp"
#include "refine/fit.hpp"

namespace scp::tools::crb::test {

// x and T̄ at every sample of `window` for this θ and initial state.
inline std::vector<double> simulate_outputs(std::span<const refine::WindowSample> window,
                                            const Eigen::Matrix<double, 9, 1>& p) {
  // Any m and R give the same trajectory for the same θ: take m = R = 1.
  drivers::sim::PlantParams params;
  params.m = 1.0;
  params.R = 1.0;
  params.b = p[0];
  params.alpha1 = p[1];
  params.k = p[2];
  params.alpha2 = p[3];
  params.Cth = 1.0 / p[5];
  params.lambda = p[4] * params.Cth;
  drivers::sim::Plant plant(params, 20);
  plant.set_state(p[6], p[7], p[8]);
  std::vector<double> out;
  out.reserve(2 * window.size());
  for (std::size_t k = 0; k < window.size(); ++k) {
    if (k > 0) plant.step(window[k].voltage, window[k].t - window[k - 1].t);
    out.push_back(plant.x());
    out.push_back(plant.tbar());
  }
  return out;
}

inline refine::Matrix6 finite_difference_crb(std::span<const refine::WindowSample> window,
                                             const refine::Vector6& theta,
                                             const refine::InitialState& initial,
                                             const refine::Vector2& noise_sigma) {
  Eigen::Matrix<double, 9, 1> p;
  p << theta, initial;
  const std::array<double, 3> state_step{1e-9, 1e-8, 1e-4};  // m, m/s, °C
  const Eigen::Index n = static_cast<Eigen::Index>(2 * window.size());
  Eigen::MatrixXd jac(n, 9);
  for (int j = 0; j < 9; ++j) {
    const double h = j < 6 ? 1e-5 * std::abs(p[j]) : state_step[static_cast<std::size_t>(j - 6)];
    Eigen::Matrix<double, 9, 1> up = p, down = p;
    up[j] += h;
    down[j] -= h;
    const auto yu = simulate_outputs(window, up);
    const auto yd = simulate_outputs(window, down);
    for (Eigen::Index r = 0; r < n; ++r) {
      const auto u = static_cast<std::size_t>(r);
      jac(r, j) = (yu[u] - yd[u]) / (2.0 * h) / noise_sigma[r % 2];
    }
  }
  // Column scaling and QR (not the normal equations): the mechanical columns are nearly
  // collinear, and JᵀJ would square their condition number.
  const Eigen::Matrix<double, 9, 1> scale = jac.colwise().norm().transpose();
  const Eigen::MatrixXd js = jac * scale.cwiseInverse().asDiagonal();
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(js);
  const Eigen::Matrix<double, 9, 9> r = qr.matrixQR().topRows<9>().triangularView<Eigen::Upper>();
  const Eigen::Matrix<double, 9, 9> r_inv =
      r.triangularView<Eigen::Upper>().solve(Eigen::Matrix<double, 9, 9>::Identity());
  const Eigen::Matrix<double, 9, 9> cov = scale.cwiseInverse().asDiagonal() *
                                          (r_inv * r_inv.transpose()) *
                                          scale.cwiseInverse().asDiagonal();
  return cov.topLeftCorner<6, 6>();
}

}  // namespace scp::tools::crb::test

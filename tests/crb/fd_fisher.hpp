#pragma once
// An independent Cramér–Rao bound for the tests of scp-crb: the Fisher information JᵀJ of the
// samples x and T̄ (each divided by its noise sd) with J by central finite differences of
// drivers/sim's RK4 plant, not of refine/'s exact discretization, over θ and the initial state
// (x, ẋ, T̄). The voltage of each sample is held over the interval before it, as a DAC holds it.

#include <Eigen/Dense>
#include <array>
#include <cmath>
#include <span>
#include <vector>

#include "drivers/sim/plant.hpp"
#include "refine/fit.hpp"

namespace scp::tools::crb::test {

// The rows of `window` where the held voltage steps by more than `step_v`, the switches of a
// PRBS.
inline std::vector<std::size_t> switch_rows(std::span<const refine::WindowSample> window,
                                            double step_v) {
  std::vector<std::size_t> rows;
  for (std::size_t k = 1; k < window.size(); ++k)
    if (std::abs(window[k].voltage - window[k - 1].voltage) > step_v) rows.push_back(k);
  return rows;
}

// x and T̄ at every sample of `window` for this θ and initial state, each voltage held over the
// interval before its sample, but each switch of `rows` a fraction `phases` of its interval late:
// the previous row's voltage held until then, the row's after. Any m and R give the same
// trajectory for the same θ: m = R = 1.
inline std::vector<double> simulate_switched(std::span<const refine::WindowSample> window,
                                             const Eigen::Matrix<double, 9, 1>& p,
                                             const std::vector<std::size_t>& rows,
                                             const Eigen::VectorXd& phases) {
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
  std::size_t next = 0;
  for (std::size_t k = 0; k < window.size(); ++k) {
    if (k > 0) {
      const double dt = window[k].t - window[k - 1].t;
      if (next < rows.size() && rows[next] == k) {
        const double phase = phases[static_cast<Eigen::Index>(next++)];
        plant.step(window[k - 1].voltage, phase * dt);
        plant.step(window[k].voltage, (1.0 - phase) * dt);
      } else {
        plant.step(window[k].voltage, dt);
      }
    }
    out.push_back(plant.x());
    out.push_back(plant.tbar());
  }
  return out;
}

// θ's block of the bound from a Jacobian whose rows are divided by their noise sd and whose first
// six columns are θ's. Column scaling and QR (not the normal equations): the mechanical columns
// are nearly collinear, and JᵀJ would square their condition number.
inline refine::Matrix6 theta_bound_of(const Eigen::MatrixXd& jac) {
  const Eigen::Index columns = jac.cols();
  const Eigen::VectorXd scale = jac.colwise().norm().transpose();
  const Eigen::MatrixXd js = jac * scale.cwiseInverse().asDiagonal();
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(js);
  const Eigen::MatrixXd r = qr.matrixQR().topRows(columns).triangularView<Eigen::Upper>();
  const Eigen::MatrixXd r_inv =
      r.triangularView<Eigen::Upper>().solve(Eigen::MatrixXd::Identity(columns, columns));
  const Eigen::MatrixXd cov = scale.cwiseInverse().asDiagonal() * (r_inv * r_inv.transpose()) *
                              scale.cwiseInverse().asDiagonal();
  return cov.topLeftCorner<6, 6>();
}

// The Jacobian of the samples (each divided by its noise sd) over θ, the initial state and the
// phases of the switches of `rows` (at ½), with the phases' prior (variance 1/12) as rows of its
// own: central finite differences of drivers/sim's plant.
inline Eigen::MatrixXd finite_difference_jacobian(std::span<const refine::WindowSample> window,
                                                  const refine::Vector6& theta,
                                                  const refine::InitialState& initial,
                                                  const refine::Vector2& noise_sigma,
                                                  const std::vector<std::size_t>& rows) {
  Eigen::Matrix<double, 9, 1> p;
  p << theta, initial;
  const auto switches = static_cast<Eigen::Index>(rows.size());
  const Eigen::VectorXd phases = Eigen::VectorXd::Constant(switches, 0.5);
  const Eigen::Index columns = 9 + switches;
  const auto samples = static_cast<Eigen::Index>(2 * window.size());
  Eigen::MatrixXd jac = Eigen::MatrixXd::Zero(samples + switches, columns);
  const std::array<double, 3> state_step{1e-9, 1e-8, 1e-4};  // m, m/s, °C
  for (Eigen::Index j = 0; j < columns; ++j) {
    Eigen::Matrix<double, 9, 1> up = p, down = p;
    Eigen::VectorXd up_phases = phases, down_phases = phases;
    double h = 1e-3;  // of an interval
    if (j < 9) {
      h = j < 6 ? 1e-5 * std::abs(p[j]) : state_step[static_cast<std::size_t>(j - 6)];
      up[j] += h;
      down[j] -= h;
    } else {
      up_phases[j - 9] += h;
      down_phases[j - 9] -= h;
    }
    const auto yu = simulate_switched(window, up, rows, up_phases);
    const auto yd = simulate_switched(window, down, rows, down_phases);
    for (Eigen::Index r = 0; r < samples; ++r) {
      const auto u = static_cast<std::size_t>(r);
      jac(r, j) = (yu[u] - yd[u]) / (2.0 * h) / noise_sigma[r % 2];
    }
  }
  for (Eigen::Index i = 0; i < switches; ++i) jac(samples + i, 9 + i) = std::sqrt(12.0);
  return jac;
}

// The bound of θ with the switches of `rows` at phases of their own, unknowns beside θ and the
// initial state, each with the prior of a switch anywhere in its interval (variance 1/12 about ½,
// where they are taken to be).
inline refine::Matrix6 finite_difference_crb_with_phases(
    std::span<const refine::WindowSample> window, const refine::Vector6& theta,
    const refine::InitialState& initial, const refine::Vector2& noise_sigma,
    const std::vector<std::size_t>& rows) {
  return theta_bound_of(finite_difference_jacobian(window, theta, initial, noise_sigma, rows));
}

// The bound of θ with the voltage's delay d unknown beside θ and the initial state (no prior):
// every switch of `window` (each row whose voltage differs from the previous row's) d later than
// its sample, the column ∂/∂d by a forward difference at d = 0 (a switch cannot move before its
// sample), d's step a thousandth of the first interval.
inline refine::Matrix6 finite_difference_crb_with_delay(
    std::span<const refine::WindowSample> window, const refine::Vector6& theta,
    const refine::InitialState& initial, const refine::Vector2& noise_sigma) {
  Eigen::Matrix<double, 9, 1> p;
  p << theta, initial;
  const std::vector<std::size_t> rows = switch_rows(window, 0.0);
  const auto switches = static_cast<Eigen::Index>(rows.size());
  const double h = 1e-3;  // of an interval
  const auto y0 = simulate_switched(window, p, rows, Eigen::VectorXd::Zero(switches));
  const auto yd = simulate_switched(window, p, rows, Eigen::VectorXd::Constant(switches, h));
  const double step = h * (window[1].t - window[0].t);
  Eigen::MatrixXd jac = finite_difference_jacobian(window, theta, initial, noise_sigma, {});
  jac.conservativeResize(Eigen::NoChange, jac.cols() + 1);
  for (std::size_t r = 0; r < y0.size(); ++r)
    jac(static_cast<Eigen::Index>(r), jac.cols() - 1) =
        (yd[r] - y0[r]) / step / noise_sigma[static_cast<Eigen::Index>(r % 2)];
  return theta_bound_of(jac);
}

// The bound without phases: θ and the initial state alone.
inline refine::Matrix6 finite_difference_crb(std::span<const refine::WindowSample> window,
                                             const refine::Vector6& theta,
                                             const refine::InitialState& initial,
                                             const refine::Vector2& noise_sigma) {
  return finite_difference_crb_with_phases(window, theta, initial, noise_sigma, {});
}

}  // namespace scp::tools::crb::test

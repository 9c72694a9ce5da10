#include "refine/heater_power.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "refine/parameters.hpp"

namespace scp::refine {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// The voltage that drove row k's current: the row's own, or with `after` the row before's (its
// command was held over the interval that ends at row k).
double driving_voltage(std::span<const WindowSample> w, std::size_t k, VoltageInterval interval) {
  return interval == VoltageInterval::after ? w[k - 1].voltage : w[k].voltage;
}

// The true T̄ at row k: the recorded one less the ambient's offset and drift, and ahead of it by
// the sensor's lag (first order: T̄_true ≈ y + τs·dy/dt, dy/dt by a central difference over ±τs so
// that the sensor noise it amplifies stays below the noise of the row itself).
double true_tbar(std::span<const WindowSample> w, std::size_t k, const Nuisance& n) {
  double tbar = w[k].tbar - n.ambient_offset.value - n.ambient_drift.value * (w[k].t - w[0].t);
  const double lag = n.sensor_lag.value;
  if (!(lag > 0.0)) return tbar;
  const auto h = static_cast<std::size_t>(std::max(1.0, std::round(lag / mean_sample_period(w))));
  const std::size_t lo = k >= h ? k - h : 0, hi = std::min(k + h, w.size() - 1);
  if (hi == lo) return tbar;
  const double slope = (w[hi].tbar - w[lo].tbar) / (w[hi].t - w[lo].t) - n.ambient_drift.value;
  return tbar + lag * slope;
}

}  // namespace

bool measures_current(std::span<const WindowSample> window) noexcept {
  if (window.empty()) return false;
  return std::all_of(window.begin(), window.end(),
                     [](const WindowSample& s) { return std::isfinite(s.current); });
}

HeaterResistance regress_resistance(std::span<const WindowSample> w, VoltageInterval interval,
                                    const Nuisance& nuisance) {
  HeaterResistance out;
  out.measured = true;
  out.r0_ohm = kNaN;
  if (w.size() < 3) return out;
  // Normal equations of V = a·I + b·I·T̄ (a = R0, b = R0·ρ).
  Eigen::Matrix2d xtx = Eigen::Matrix2d::Zero();
  Eigen::Vector2d xty = Eigen::Vector2d::Zero();
  double yty = 0.0;
  for (std::size_t k = 1; k < w.size(); ++k) {
    const double v = driving_voltage(w, k, interval), i = w[k].current;
    const Eigen::Vector2d x(i, i * true_tbar(w, k, nuisance));
    xtx += x * x.transpose();
    xty += x * v;
    yty += v * v;
  }
  const double rows = static_cast<double>(w.size() - 1);
  if (!(xtx(0, 0) > 0.0) || !std::isfinite(xtx.sum())) return out;
  const Eigen::LDLT<Eigen::Matrix2d> ldlt(xtx);
  const Eigen::Vector2d ab = ldlt.solve(xty);
  if (ldlt.info() != Eigen::Success || !ab.allFinite() || !(ab[0] > 0.0)) return out;
  const double rss = std::max(0.0, yty - ab.dot(xty));
  const Eigen::Matrix2d cov =
      (rss / std::max(1.0, rows - 2.0)) * ldlt.solve(Eigen::Matrix2d::Identity());
  out.r0_ohm = ab[0];
  out.r0_sigma_ohm = std::sqrt(std::max(0.0, cov(0, 0)));
  out.rho = ab[1] / ab[0];
  // ρ = b/a: its gradient (−b/a², 1/a) through the pair's covariance.
  const Eigen::Vector2d g(-ab[1] / (ab[0] * ab[0]), 1.0 / ab[0]);
  out.rho_sigma = std::sqrt(std::max(0.0, g.dot(cov * g)));
  return out;
}

double reference_resistance(std::span<const WindowSample> window, VoltageInterval interval) {
  const double r0 = regress_resistance(window, interval).r0_ohm;
  return std::isfinite(r0) && r0 > 0.0 ? r0 : 1.0;
}

namespace {

// The conductance at row k: G(t) = a + b·(t − t_k) fitted by least squares to I = V·G(t) over the
// rows within ±half_width (I noisy, V not), a returned. The slope keeps the window's weights, V²,
// from shifting the estimate in time where V changes (a constant G would: a lag of the heater's
// R(T̄) that the fit cannot tell from the sensor's).
double local_conductance(std::span<const WindowSample> rows, std::size_t k,
                         std::size_t half_width) {
  const std::size_t lo = k > half_width ? k - half_width : 0;
  const std::size_t hi = std::min(rows.size() - 1, k + half_width);
  Eigen::Matrix2d a = Eigen::Matrix2d::Zero();
  Eigen::Vector2d y = Eigen::Vector2d::Zero();
  for (std::size_t j = lo; j <= hi; ++j) {
    const double v = rows[j].voltage;
    const Eigen::Vector2d x(v, v * (rows[j].t - rows[k].t));
    a += x * x.transpose();
    y += x * rows[j].current;
  }
  if (!(a(0, 0) > 0.0)) return 0.0;
  const double det = a.determinant();
  // Too little spread of V·τ for a slope (V ≈ 0 on one side): the weighted mean.
  if (!(det > 1e-12 * a(0, 0) * a(1, 1))) return std::max(0.0, y[0] / a(0, 0));
  return std::max(0.0, (a(1, 1) * y[0] - a(0, 1) * y[1]) / det);
}

}  // namespace

void use_measured_power(std::span<WindowSample> rows, double r_ref, std::size_t half_width) {
  const std::size_t n = rows.size();
  std::vector<double> conductance(n, 0.0);
  for (std::size_t k = 0; k < n; ++k) conductance[k] = local_conductance(rows, k, half_width);
  for (std::size_t k = 0; k < n; ++k) {
    // A held voltage heats with the conductance's mean over its interval, which the interval's
    // two ends give to O(Δ²); the end's alone would lag the heater's R(T̄) by half a period. A
    // ramp is read at its samples.
    const double g = rows[k].voltage_ramp || k == 0 ? conductance[k]
                                                    : 0.5 * (conductance[k - 1] + conductance[k]);
    rows[k].voltage = std::abs(rows[k].voltage) * std::sqrt(r_ref * g);
  }
}

void publish_measured_power(std::span<const WindowSample> window, FitResult& result) {
  const double r_ref = reference_resistance(window, result.voltage_interval);
  HeaterResistance heater = regress_resistance(window, result.voltage_interval, result.nuisance);
  heater.reference_ohm = r_ref;
  result.heater = heater;
  if (!std::isfinite(heater.r0_ohm)) return;  // θ6 stays 1/(R_ref·Cth): the reference is 1 Ω
  const double scale = r_ref / heater.r0_ohm;
  result.theta[kHeating] *= scale;
  const double r0_rel = heater.r0_sigma_ohm / heater.r0_ohm;
  for (Matrix6* c : {&result.covariance, &result.covariance_white}) {
    c->row(kHeating) *= scale;
    c->col(kHeating) *= scale;
    (*c)(kHeating, kHeating) += std::pow(result.theta[kHeating] * r0_rel, 2);
  }
  result.sigma_white = result.covariance_white.diagonal().cwiseMax(0.0).cwiseSqrt();
  result.sigma = result.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
}

}  // namespace scp::refine

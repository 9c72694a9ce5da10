#include "health/trend.hpp"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>

#include "health/covariance.hpp"

namespace scp::health {

namespace {

double overlap(const WindowEstimate& a, const WindowEstimate& b) noexcept {
  return std::max(0.0, std::min(a.t_end, b.t_end) - std::max(a.t_begin, b.t_begin));
}

// Least-squares weights per window (rows) and parameter (columns): θ̂ at t_eval is
// Σ_t prediction(t, i)·θ̂_t,i, the slope Σ_t slope(t, i)·θ̂_t,i.
struct Weights {
  Eigen::MatrixXd prediction, slope;
};

bool parameter_free(std::span<const WindowEstimate> windows, int i) noexcept {
  for (const auto& w : windows)
    if (!(w.covariance(i, i) > 0.0)) return false;
  return true;
}

Weights least_squares_weights(std::span<const WindowEstimate> windows, double t_eval,
                              bool with_slope, const ParameterMask& free) {
  const auto n = static_cast<Eigen::Index>(windows.size());
  Weights w{Eigen::MatrixXd::Zero(n, kParams), Eigen::MatrixXd::Zero(n, kParams)};
  for (int i = 0; i < kParams; ++i) {
    if (!free[i]) {
      w.prediction(n - 1, i) = 1.0;
      continue;
    }
    double s0 = 0.0, s1 = 0.0;
    for (Eigen::Index t = 0; t < n; ++t) {
      const double wt = 1.0 / windows[t].covariance(i, i);
      s0 += wt;
      s1 += wt * windows[t].midpoint();
    }
    const double center = s1 / s0;
    double s2 = 0.0;
    for (Eigen::Index t = 0; t < n; ++t) {
      const double x = windows[t].midpoint() - center;
      s2 += x * x / windows[t].covariance(i, i);
    }
    const bool slope = with_slope && s2 > 0.0;
    for (Eigen::Index t = 0; t < n; ++t) {
      const double wt = 1.0 / windows[t].covariance(i, i);
      const double x = windows[t].midpoint() - center;
      w.prediction(t, i) = wt / s0 + (slope ? (t_eval - center) * wt * x / s2 : 0.0);
      w.slope(t, i) = slope ? wt * x / s2 : 0.0;
    }
  }
  return w;
}

// Adds Cov(θ̂_t, θ̂_s) = k weighted by the least-squares weights of t and s.
void accumulate(TrendFit& fit, Vector6& slope_variance, const Weights& w, Eigen::Index t,
                Eigen::Index s, const Matrix6& k) noexcept {
  for (int i = 0; i < kParams; ++i) {
    slope_variance[i] += w.slope(t, i) * w.slope(s, i) * k(i, i);
    for (int j = 0; j < kParams; ++j)
      fit.level_covariance(i, j) += w.prediction(t, i) * w.prediction(s, j) * k(i, j);
  }
}

}  // namespace

Matrix6 window_cross_covariance(const WindowEstimate& a, const WindowEstimate& b) noexcept {
  const double shared = overlap(a, b);
  if (!(shared > 0.0) || !(a.length() > 0.0) || !(b.length() > 0.0)) return Matrix6::Zero();
  return 0.5 * shared * (a.covariance / b.length() + b.covariance / a.length());
}

TrendFit fit_trend(std::span<const WindowEstimate> windows, double t_eval, bool with_slope) {
  TrendFit fit;
  if (windows.empty()) return fit;
  const auto n = static_cast<Eigen::Index>(windows.size());
  ParameterMask free{};
  for (int i = 0; i < kParams; ++i) free[i] = parameter_free(windows, i);
  const bool slope = with_slope && windows.front().midpoint() < windows.back().midpoint();
  const Weights w = least_squares_weights(windows, t_eval, slope, free);
  fit.valid = true;
  fit.with_slope = slope;
  fit.windows = static_cast<int>(n);
  fit.t_eval = t_eval;
  fit.data_span = windows.back().t_end - windows.front().t_begin;
  Vector6 slope_variance = Vector6::Zero();
  for (Eigen::Index t = 0; t < n; ++t) {
    for (int i = 0; i < kParams; ++i) {
      fit.level[i] += w.prediction(t, i) * windows[t].theta[i];
      fit.slope[i] += w.slope(t, i) * windows[t].theta[i];
    }
    // Only windows that share data are correlated: in time order, the later ones up to the first
    // that starts after this one ends (each pair counted both ways).
    accumulate(fit, slope_variance, w, t, t, windows[t].covariance);
    for (Eigen::Index s = t + 1; s < n && windows[s].t_begin < windows[t].t_end; ++s) {
      const Matrix6 k = window_cross_covariance(windows[t], windows[s]);
      accumulate(fit, slope_variance, w, t, s, k);
      accumulate(fit, slope_variance, w, s, t, k);
    }
  }
  // Overlapping windows whose weakly determined directions differ make the sandwich indefinite
  // where the weights extrapolate (two windows 30 s apart predicted 60 s ahead weigh 3 and −2).
  fit.level_covariance = positive_semidefinite(fit.level_covariance);
  fit.slope_sigma = slope_variance.cwiseMax(0.0).cwiseSqrt();
  return fit;
}

}  // namespace scp::health

#include "health/drift_naming.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "health/trend.hpp"

namespace scp::health {

namespace {

constexpr int kStiffness = 2;  // θ3 = k/m, the ratios' divisor
// The ratios' slots in a pseudo-window: θ1/θ3, θ2/θ3, θ4/θ3 where θ1, θ2, θ4 are.
constexpr std::array<int, 3> kRatioOf = {0, 1, 3};

// The window with θ1, θ2, θ4 replaced by their ratios to θ3 and the rest held known (zero
// variance: trend.hpp then fits no slope for them). Its covariance by the delta method.
WindowEstimate ratio_window(const WindowEstimate& w) {
  WindowEstimate r;
  r.t_begin = w.t_begin;
  r.t_end = w.t_end;
  const double k = w.theta[kStiffness];
  Matrix6 jacobian = Matrix6::Zero();
  for (const int i : kRatioOf) {
    r.theta[i] = w.theta[i] / k;
    jacobian(i, i) = 1.0 / k;
    jacobian(i, kStiffness) = -w.theta[i] / (k * k);
  }
  r.covariance = jacobian * w.covariance * jacobian.transpose();
  return r;
}

// √(χ²/(n − 2)) of the windows that share no data about the fitted line, at least 1; 0 when
// fewer than three such windows exist.
Vector6 scatter_factor(std::span<const WindowEstimate> ratios, const TrendFit& fit) {
  std::vector<const WindowEstimate*> disjoint;
  for (auto w = ratios.rbegin(); w != ratios.rend(); ++w)
    if (disjoint.empty() || w->t_end <= disjoint.back()->t_begin) disjoint.push_back(&*w);
  Vector6 factor = Vector6::Zero();
  const auto n = static_cast<double>(disjoint.size());
  if (n < 3.0) return factor;
  for (const int i : kRatioOf) {
    double chi2 = 0.0;
    for (const WindowEstimate* w : disjoint) {
      const double line = fit.level[i] + fit.slope[i] * (w->midpoint() - fit.t_eval);
      const double variance = w->covariance(i, i);
      if (variance > 0.0) chi2 += (w->theta[i] - line) * (w->theta[i] - line) / variance;
    }
    factor[i] = std::sqrt(std::max(1.0, chi2 / (n - 2.0)));
  }
  return factor;
}

// Each ratio's rate relative to its level, per hour, with σ (widened by the scatter).
struct RatioRates {
  bool valid = false;
  Vector6 rate = Vector6::Zero(), sigma = Vector6::Zero();
};

RatioRates ratio_rates(std::span<const WindowEstimate> windows) {
  RatioRates r;
  std::vector<WindowEstimate> ratios;
  for (const auto& w : windows)
    if (w.theta[kStiffness] != 0.0 && w.covariance.allFinite()) ratios.push_back(ratio_window(w));
  if (ratios.size() < 3) return r;
  const TrendFit fit = fit_trend(ratios, ratios.back().midpoint(), true);
  if (!fit.with_slope) return r;
  const Vector6 factor = scatter_factor(ratios, fit);
  for (const int i : kRatioOf) {
    if (!(factor[i] > 0.0) || !(fit.slope_sigma[i] > 0.0) || fit.level[i] == 0.0) return r;
    r.rate[i] = 3600.0 * fit.slope[i] / std::abs(fit.level[i]);
    r.sigma[i] = 3600.0 * factor[i] * fit.slope_sigma[i] / std::abs(fit.level[i]);
  }
  r.valid = true;
  return r;
}

// The parameter the moving ratios single out, with its relative rate and σ; −1 if none. k moves
// every ratio by the same relative rate with the opposite sign (their weighted mean).
int single_out(const RatioRates& r, double z, double& relative, double& relative_sigma) {
  std::array<bool, kParams> moving{};
  int count = 0, only = -1;
  for (const int i : kRatioOf) {
    moving[i] = std::abs(r.rate[i]) > z * r.sigma[i];
    if (moving[i]) {
      ++count;
      only = i;
    }
  }
  if (count == 1) {
    relative = r.rate[only];
    relative_sigma = r.sigma[only];
    return only;
  }
  const auto agree = [&](int a, int b) {
    return std::abs(r.rate[a] - r.rate[b]) <= z * std::hypot(r.sigma[a], r.sigma[b]);
  };
  if (!(moving[0] && moving[3] && agree(0, 3) && agree(0, 1) && agree(1, 3))) return -1;
  double weight = 0.0;
  relative = 0.0;
  for (const int i : kRatioOf) {
    const double w = 1.0 / (r.sigma[i] * r.sigma[i]);
    relative -= w * r.rate[i];
    weight += w;
  }
  relative /= weight;
  relative_sigma = 1.0 / std::sqrt(weight);
  return kStiffness;
}

}  // namespace

DriftName name_mechanical_drift(std::span<const WindowEstimate> windows, double z) {
  DriftName name;
  const RatioRates rates = ratio_rates(windows);
  if (!rates.valid) return name;
  double relative = 0.0, relative_sigma = 0.0;
  name.parameter = single_out(rates, z, relative, relative_sigma);
  if (name.parameter < 0) return name;
  // θ_i drifts at the ratio's relative rate while k/m holds (and at −that for k/m itself).
  const double theta = std::abs(windows.back().theta[name.parameter]);
  name.trend.tested = true;
  name.trend.relative_per_hour = relative;
  name.trend.per_hour = relative * theta;
  name.trend.sigma_per_hour = relative_sigma * theta;
  name.trend.drifting = true;
  return name;
}

}  // namespace scp::health

#include "refine/interval_averaging.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace scp::refine {

double mechanical_shift_sigma(const FitResult& a, const FitResult& b,
                              const std::array<bool, 6>& known) {
  double worst = 0.0;
  for (int i = 0; i < 4; ++i) {
    if (known[static_cast<std::size_t>(i)]) continue;
    const double z = std::abs(a.theta[i] - b.theta[i]) / a.sigma[i];
    worst = std::isfinite(z) ? std::max(worst, z) : std::numeric_limits<double>::infinity();
  }
  return worst;
}

Matrix6 interval_covariance(const FitResult& a, const FitResult& b, double statistic,
                            const std::array<bool, 6>& known) {
  Vector6 d = b.theta - a.theta;
  for (int i = 0; i < 6; ++i)
    if (known[static_cast<std::size_t>(i)] || !std::isfinite(d[i])) d[i] = 0.0;
  const double w = 1.0 / (1.0 + std::exp(0.5 * std::max(statistic, 0.0)));
  return w * d * d.transpose();
}

void add_covariance_share(FitResult& r, const Matrix6& share) {
  r.covariance += share;
  for (int i = 0; i < 6; ++i) r.sigma[i] = std::sqrt(r.sigma[i] * r.sigma[i] + share(i, i));
}

void add_interval_covariance(FitResult& r, const Matrix6& share) {
  add_covariance_share(r, share);
  r.interval_covariance = share;
}

}  // namespace scp::refine

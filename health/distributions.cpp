// Normal and χ² tails (the χ² tail is refine's incomplete gamma: one implementation), quantiles
// by bisection on the logarithm of the tail, which stays well conditioned at 1e-12.
#include "health/distributions.hpp"

#include <cmath>
#include <numbers>

#include "refine/probability.hpp"

namespace scp::health {

namespace {

// The x in [lo, hi] where log tail(x) = log target, tail decreasing.
template <typename Tail>
double invert_decreasing(Tail tail, double target, double lo, double hi) noexcept {
  const double log_target = std::log(target);
  while (std::log(tail(hi)) > log_target) hi *= 2.0;
  for (int i = 0; i < 200 && hi - lo > 1e-12 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    if (std::log(tail(mid)) > log_target) {
      lo = mid;
    } else {
      hi = mid;
    }
  }
  return 0.5 * (lo + hi);
}

}  // namespace

double normal_density(double z) noexcept {
  return std::exp(-0.5 * z * z) / std::sqrt(2.0 * std::numbers::pi);
}

double normal_upper_tail(double z) noexcept {
  return 0.5 * std::erfc(z / std::numbers::sqrt2);
}

double normal_upper_quantile(double probability) noexcept {
  if (!(probability > 0.0 && probability < 1.0)) return std::nan("");
  if (probability > 0.5) return -normal_upper_quantile(1.0 - probability);
  return invert_decreasing([](double z) { return normal_upper_tail(z); }, probability, 0.0, 8.0);
}

namespace {

// ln Γ(x) without std::lgamma's write to glibc's global `signgam` (the monitor runs on the loop's
// thread while an offline replay's fits run on others; refine/probability.cpp does the same).
double log_gamma(double x) noexcept {
  int sign = 0;
  return ::lgamma_r(x, &sign);
}

}  // namespace

double chi_square_density(double x, int dof) noexcept {
  if (!(x > 0.0) || dof < 1) return 0.0;
  const double k = 0.5 * dof;
  return std::exp((k - 1.0) * std::log(x) - 0.5 * x - k * std::numbers::ln2 - log_gamma(k));
}

double chi_square_upper_tail(double x, int dof) noexcept {
  if (dof < 1) return std::nan("");
  return refine::chi_square_survival(x, dof);
}

double chi_square_upper_quantile(double probability, int dof) noexcept {
  if (!(probability > 0.0 && probability < 1.0) || dof < 1) return std::nan("");
  return invert_decreasing([dof](double x) { return chi_square_upper_tail(x, dof); }, probability,
                           0.0, 4.0 * dof + 20.0);
}

}  // namespace scp::health

// Normal and χ² tails: the incomplete gamma by its power series below a + 1 and by Lentz's
// continued fraction above (each converges fast where the other is slow), quantiles by
// bisection on the logarithm of the tail, which stays well conditioned at 1e-12.
#include "health/distributions.hpp"

#include <cmath>
#include <numbers>

namespace scp::health {

namespace {

// P(a, x) by the series e^{−x} x^a / Γ(a+1) · Σ x^n / ((a+1)…(a+n)), for x < a + 1.
double lower_gamma_series(double a, double x) noexcept {
  double term = 1.0 / a, sum = term;
  for (int n = 1; n < 1000; ++n) {
    term *= x / (a + n);
    sum += term;
    if (std::abs(term) < std::abs(sum) * 1e-16) break;
  }
  return sum * std::exp(-x + a * std::log(x) - std::lgamma(a));
}

// Q(a, x) by the continued fraction of Γ(a, x), modified Lentz, for x ≥ a + 1.
double upper_gamma_fraction(double a, double x) noexcept {
  constexpr double tiny = 1e-300;
  double b = x + 1.0 - a, c = 1.0 / tiny, d = 1.0 / b, h = d;
  for (int i = 1; i < 1000; ++i) {
    const double an = -i * (i - a);
    b += 2.0;
    d = an * d + b;
    if (std::abs(d) < tiny) d = tiny;
    c = b + an / c;
    if (std::abs(c) < tiny) c = tiny;
    d = 1.0 / d;
    const double delta = d * c;
    h *= delta;
    if (std::abs(delta - 1.0) < 1e-16) break;
  }
  return std::exp(-x + a * std::log(x) - std::lgamma(a)) * h;
}

double regularized_upper_gamma(double a, double x) noexcept {
  if (!(x > 0.0)) return 1.0;
  if (x < a + 1.0) return 1.0 - lower_gamma_series(a, x);
  return upper_gamma_fraction(a, x);
}

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

double chi_square_density(double x, int dof) noexcept {
  if (!(x > 0.0) || dof < 1) return 0.0;
  const double k = 0.5 * dof;
  return std::exp((k - 1.0) * std::log(x) - 0.5 * x - k * std::numbers::ln2 - std::lgamma(k));
}

double chi_square_upper_tail(double x, int dof) noexcept {
  if (dof < 1) return std::nan("");
  return regularized_upper_gamma(0.5 * dof, 0.5 * x);
}

double chi_square_upper_quantile(double probability, int dof) noexcept {
  if (!(probability > 0.0 && probability < 1.0) || dof < 1) return std::nan("");
  return invert_decreasing([dof](double x) { return chi_square_upper_tail(x, dof); }, probability,
                           0.0, 4.0 * dof + 20.0);
}

}  // namespace scp::health

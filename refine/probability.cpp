#include "refine/probability.hpp"

#include <cmath>
#include <limits>

namespace scp::refine {

namespace {

constexpr double kEps = 1e-15;
constexpr double kTiny = 1e-300;
// Enough for a = 2e5 (a 300 s window's noise-ratio test: χ² of ~3e5 degrees of freedom), where
// both expansions need O(√a) terms.
constexpr int kMaxTerms = 100000;

// ln Γ(x) without std::lgamma's write to glibc's global `signgam`: two fits on two threads (the
// offline replay's lanes) would race on it. Γ > 0 for every x > 0 these distributions use.
double log_gamma(double x) noexcept {
  int sign = 0;
  return ::lgamma_r(x, &sign);
}

// P(a, x) by its series, for x < a + 1.
double lower_gamma_series(double a, double x) noexcept {
  double term = 1.0 / a, sum = term;
  for (int n = 1; n < kMaxTerms; ++n) {
    term *= x / (a + n);
    sum += term;
    if (std::abs(term) < std::abs(sum) * kEps) break;
  }
  return sum * std::exp(-x + a * std::log(x) - log_gamma(a));
}

// Q(a, x) by its continued fraction (modified Lentz), for x ≥ a + 1.
double upper_gamma_fraction(double a, double x) noexcept {
  double b = x + 1.0 - a, c = 1.0 / kTiny, d = 1.0 / b, h = d;
  for (int i = 1; i < kMaxTerms; ++i) {
    const double an = -i * (i - a);
    b += 2.0;
    d = an * d + b;
    if (std::abs(d) < kTiny) d = kTiny;
    c = b + an / c;
    if (std::abs(c) < kTiny) c = kTiny;
    d = 1.0 / d;
    const double delta = d * c;
    h *= delta;
    if (std::abs(delta - 1.0) < kEps) break;
  }
  return std::exp(-x + a * std::log(x) - log_gamma(a)) * h;
}

// The continued fraction of I_x(a, b) (modified Lentz).
double beta_fraction(double a, double b, double x) noexcept {
  const double qab = a + b, qap = a + 1.0, qam = a - 1.0;
  double c = 1.0, d = 1.0 - qab * x / qap;
  if (std::abs(d) < kTiny) d = kTiny;
  d = 1.0 / d;
  double h = d;
  for (int m = 1; m < kMaxTerms; ++m) {
    const int m2 = 2 * m;
    double aa = m * (b - m) * x / ((qam + m2) * (a + m2));
    d = 1.0 + aa * d;
    if (std::abs(d) < kTiny) d = kTiny;
    c = 1.0 + aa / c;
    if (std::abs(c) < kTiny) c = kTiny;
    d = 1.0 / d;
    h *= d * c;
    aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
    d = 1.0 + aa * d;
    if (std::abs(d) < kTiny) d = kTiny;
    c = 1.0 + aa / c;
    if (std::abs(c) < kTiny) c = kTiny;
    d = 1.0 / d;
    const double delta = d * c;
    h *= delta;
    if (std::abs(delta - 1.0) < kEps) break;
  }
  return h;
}

// The regularized incomplete beta function I_x(a, b).
double incomplete_beta(double a, double b, double x) noexcept {
  if (x <= 0.0) return 0.0;
  if (x >= 1.0) return 1.0;
  const double front = std::exp(log_gamma(a + b) - log_gamma(a) - log_gamma(b) + a * std::log(x) +
                                b * std::log1p(-x));
  // The fraction converges fast for x below the mean a/(a + b); above it, by symmetry.
  if (x < (a + 1.0) / (a + b + 2.0)) return front * beta_fraction(a, b, x) / a;
  return 1.0 - front * beta_fraction(b, a, 1.0 - x) / b;
}

}  // namespace

double chi_square_survival(double x, double dof) noexcept {
  if (!(dof > 0.0) || std::isnan(x)) return std::numeric_limits<double>::quiet_NaN();
  if (x <= 0.0) return 1.0;
  if (std::isinf(x)) return 0.0;
  const double a = 0.5 * dof, h = 0.5 * x;
  return h < a + 1.0 ? 1.0 - lower_gamma_series(a, h) : upper_gamma_fraction(a, h);
}

double f_survival(double f, double dof1, double dof2) noexcept {
  if (!(dof1 > 0.0) || !(dof2 > 0.0) || std::isnan(f))
    return std::numeric_limits<double>::quiet_NaN();
  if (f <= 0.0) return 1.0;
  if (std::isinf(f)) return 0.0;
  // P(F > f) = I_{d2/(d2 + d1 f)}(d2/2, d1/2).
  return incomplete_beta(0.5 * dof2, 0.5 * dof1, dof2 / (dof2 + dof1 * f));
}

double sidak_level(double family, int tests) noexcept {
  if (tests <= 1) return family;
  return -std::expm1(std::log1p(-family) / tests);
}

}  // namespace scp::refine

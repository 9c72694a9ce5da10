#include "health/scan_threshold.hpp"

#include <algorithm>
#include <cmath>

#include "health/distributions.hpp"

namespace scp::health {

double siegmund_nu(double x) noexcept {
  if (!(x > 1e-8)) return 1.0;
  const double half = 0.5 * x;
  const double cdf = 1.0 - normal_upper_tail(half);
  return (2.0 / x) * (cdf - 0.5) / (half * cdf + normal_density(half));
}

double chi_square_scan_rate(double b, int dof, double beta, double spacing) noexcept {
  const double independent = chi_square_upper_tail(b, dof) / spacing;
  const double local = beta * b * 2.0 * chi_square_density(b, dof) *
                       siegmund_nu(std::sqrt(2.0 * beta * spacing * b));
  return std::min(local, independent);
}

double chi_square_scan_threshold(double rate, int dof, double beta, double spacing) noexcept {
  if (!(rate > 0.0 && beta > 0.0 && spacing > 0.0)) return std::nan("");
  // The rate falls monotonically above the mode of b·f_p(b) (at b = p); search above it.
  double lo = static_cast<double>(dof), hi = 2.0 * dof + 40.0;
  if (chi_square_scan_rate(lo, dof, beta, spacing) <= rate) return lo;
  while (chi_square_scan_rate(hi, dof, beta, spacing) > rate) hi *= 2.0;
  const double log_rate = std::log(rate);
  for (int i = 0; i < 200 && hi - lo > 1e-10 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    if (std::log(chi_square_scan_rate(mid, dof, beta, spacing)) > log_rate) {
      lo = mid;
    } else {
      hi = mid;
    }
  }
  return 0.5 * (lo + hi);
}

}  // namespace scp::health

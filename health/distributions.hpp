#pragma once
// The few distribution functions the detectors' thresholds need, accurate far into the tails
// (a 30-day false-alarm design asks for tail probabilities of 1e-6..1e-9).

namespace scp::health {

// Standard normal density and upper tail P(Z > z).
double normal_density(double z) noexcept;
double normal_upper_tail(double z) noexcept;
// z with P(Z > z) = probability, 0 < probability < 1.
double normal_upper_quantile(double probability) noexcept;

// χ² with `dof` degrees of freedom: density, upper tail P(X > x) and the x with P(X > x) =
// probability. The tail is the regularized upper incomplete gamma Q(dof/2, x/2).
double chi_square_density(double x, int dof) noexcept;
double chi_square_upper_tail(double x, int dof) noexcept;
double chi_square_upper_quantile(double probability, int dof) noexcept;

}  // namespace scp::health

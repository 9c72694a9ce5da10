#pragma once
// Tail probabilities of the χ² and F distributions, for the residual tests of
// refine/validation.hpp: each test reports its p-value, and fails when it is below the test's
// level. Regularized incomplete gamma and beta functions (series and Lentz's continued fractions,
// as in Numerical Recipes §6.2, §6.4), accurate to ~1e-12 relative where the result is above
// 1e-300, and to 1e-10 absolute at worst.

namespace scp::refine {

// P(χ²_k > x) for k > 0 degrees of freedom (1 for x ≤ 0).
double chi_square_survival(double x, double dof) noexcept;

// P(F_{d1,d2} > f) (1 for f ≤ 0).
double f_survival(double f, double dof1, double dof2) noexcept;

// The per-test level that keeps the probability of any false alarm among n independent tests at
// `family` (Šidák): 1 − (1 − family)^(1/n).
double sidak_level(double family, int tests) noexcept;

}  // namespace scp::refine

// Normal and χ² tails and quantiles: against printed tables, against each other, and the
// density against the tail's derivative.
#include <gtest/gtest.h>

#include <cmath>

#include "health/distributions.hpp"

namespace scp::health {
namespace {

TEST(Distributions, NormalTailMatchesTables) {
  EXPECT_NEAR(normal_upper_tail(1.959964), 0.025, 1e-7);
  EXPECT_NEAR(normal_upper_tail(0.0), 0.5, 1e-15);
  EXPECT_NEAR(normal_upper_quantile(0.001), 3.090232, 1e-6);
  EXPECT_NEAR(normal_upper_quantile(0.975), -1.959964, 1e-6);
  // Far in the tail (a 30-day design asks for ~1e-8).
  EXPECT_NEAR(normal_upper_quantile(1e-8) / 5.612001, 1.0, 1e-6);
}

TEST(Distributions, ChiSquareQuantilesMatchTables) {
  // 0.999 points for 1..4 degrees of freedom (the refinement's bias test uses the same table).
  const double table[] = {10.828, 13.816, 16.266, 18.467};
  for (int dof = 1; dof <= 4; ++dof)
    EXPECT_NEAR(chi_square_upper_quantile(1e-3, dof), table[dof - 1], 1e-3) << dof;
  // χ²₂'s tail is e^{−x/2} exactly.
  for (double x : {0.5, 3.0, 30.0, 80.0})
    EXPECT_NEAR(chi_square_upper_tail(x, 2) / std::exp(-0.5 * x), 1.0, 1e-12) << x;
  // χ²₁ is a squared normal.
  for (double z : {0.5, 2.0, 5.0, 7.0})
    EXPECT_NEAR(chi_square_upper_tail(z * z, 1) / (2.0 * normal_upper_tail(z)), 1.0, 1e-9) << z;
}

TEST(Distributions, QuantileInvertsTheTail) {
  for (int dof : {1, 2, 3, 4, 6})
    for (double p : {0.5, 1e-2, 1e-5, 1e-9, 1e-12}) {
      const double x = chi_square_upper_quantile(p, dof);
      EXPECT_NEAR(chi_square_upper_tail(x, dof) / p, 1.0, 1e-6) << dof << " " << p;
    }
}

TEST(Distributions, DensityIsTheTailsDerivative) {
  for (int dof : {1, 2, 4, 5})
    for (double x : {0.7, 4.0, 20.0}) {
      const double h = 1e-5 * x;
      const double derivative =
          (chi_square_upper_tail(x - h, dof) - chi_square_upper_tail(x + h, dof)) / (2.0 * h);
      EXPECT_NEAR(chi_square_density(x, dof) / derivative, 1.0, 1e-6) << dof << " " << x;
    }
}

}  // namespace
}  // namespace scp::health

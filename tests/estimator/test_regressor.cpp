#include <gtest/gtest.h>

#include "estimator/regressor.hpp"

namespace scp::estimator {
namespace {

TEST(Regressor, EntriesOfEquationSix) {
  // ẋ = 2e-4, T̄ = 30, x = -1.5e-3, V = 2.5 → row 1 [−2e-4, −6e-3, 1.5e-3, −30, 0, 0],
  // row 2 [0, 0, 0, 0, −30, 6.25].
  const Regressor w = regressor(2e-4, 30.0, -1.5e-3, 2.5);
  const double expected[2][6] = {{-2e-4, -6e-3, 1.5e-3, -30.0, 0.0, 0.0},
                                 {0.0, 0.0, 0.0, 0.0, -30.0, 6.25}};
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 6; ++c) EXPECT_NEAR(w(r, c), expected[r][c], 1e-15) << r << "," << c;
  }
}

TEST(Regressor, ReproducesPlantAcceleration) {
  // a = W θ (eq. (8)) against the model written out by hand with Table I.
  const double xdot = -3e-4, tbar = 12.0, x = 2e-3, v = 1.7;
  Eigen::Matrix<double, 6, 1> theta;
  theta << 1247.0, 0.8, 1813.0, 0.1, 0.054 / 0.909, 1.0 / 0.909;
  const Eigen::Vector2d a = regressor(xdot, tbar, x, v) * theta;
  const double xdd = (-124.7 * xdot - 0.08 * tbar * xdot - 181.3 * x - 0.01 * tbar) / 0.1;
  const double tdot = (-0.054 * tbar + v * v / 1.0) / 0.909;
  EXPECT_NEAR(a(0), xdd, 1e-12 * std::abs(xdd));
  EXPECT_NEAR(a(1), tdot, 1e-12 * std::abs(tdot));
}

}  // namespace
}  // namespace scp::estimator

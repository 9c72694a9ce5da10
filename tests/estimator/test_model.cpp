#include <gtest/gtest.h>

#include "estimator/model.hpp"

namespace scp::estimator {
namespace {

TEST(Model, ThetaFromTableOneMatchesHandValues) {
  const Vector6 theta = theta_from_physical(table1_params());
  // Hand values: 124.7/0.1, 0.08/0.1, 181.3/0.1, 0.01/0.1, 0.0540/0.9090, 1/(1·0.9090).
  EXPECT_NEAR(theta(0), 1247.0, 1e-9);
  EXPECT_NEAR(theta(1), 0.8, 1e-12);
  EXPECT_NEAR(theta(2), 1813.0, 1e-9);
  EXPECT_NEAR(theta(3), 0.1, 1e-12);
  EXPECT_NEAR(theta(4), 0.0594059406, 1e-9);
  EXPECT_NEAR(theta(5), 1.1001100110, 1e-9);
}

TEST(Model, TableOneDefaults) {
  const PhysicalParams p = table1_params();
  EXPECT_EQ(p.m, 0.1);
  EXPECT_EQ(p.R, 1.0);
  EXPECT_EQ(p.Cth, 0.9090);
  EXPECT_EQ(p.lambda, 0.0540);
  EXPECT_EQ(p.b, 124.7);
  EXPECT_EQ(p.k, 181.3);
  EXPECT_EQ(p.alpha1, 0.08);
  EXPECT_EQ(p.alpha2, 0.01);
}

TEST(Model, RoundTripWithKnownMassAndResistance) {
  const PhysicalParams in{.m = 0.25,
                          .R = 3.5,
                          .Cth = 2.0,
                          .lambda = 0.07,
                          .b = 50.0,
                          .k = 300.0,
                          .alpha1 = 0.02,
                          .alpha2 = 0.004};
  const PhysicalParams out = physical_from_theta(theta_from_physical(in), in.m, in.R);
  EXPECT_DOUBLE_EQ(out.m, in.m);
  EXPECT_DOUBLE_EQ(out.R, in.R);
  EXPECT_NEAR(out.Cth, in.Cth, 1e-12);
  EXPECT_NEAR(out.lambda, in.lambda, 1e-14);
  EXPECT_NEAR(out.b, in.b, 1e-11);
  EXPECT_NEAR(out.k, in.k, 1e-11);
  EXPECT_NEAR(out.alpha1, in.alpha1, 1e-15);
  EXPECT_NEAR(out.alpha2, in.alpha2, 1e-15);
}

}  // namespace
}  // namespace scp::estimator

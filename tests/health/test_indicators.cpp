// Derived physical indicators: their values from θ, and the delta method's σ against a direct
// simulation of θ̂'s scatter.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <random>

#include "health/indicators.hpp"
#include "tests/health/synthetic_windows.hpp"

namespace scp::health {
namespace {

IndicatorValue at(const Indicators& v, Indicator i) {
  return v[static_cast<int>(i)];
}

TEST(Indicators, ValuesFollowFromTheta) {
  const Vector6 t = test::paper_theta();
  const Indicators v = derive_indicators(t, test::window_covariance_300s(), 2.0);
  EXPECT_DOUBLE_EQ(at(v, Indicator::thermal_time_constant).value, 1.0 / t[4]);
  EXPECT_DOUBLE_EQ(at(v, Indicator::static_gain).value, t[3] / t[2]);
  EXPECT_DOUBLE_EQ(at(v, Indicator::mechanical_time_constant).value, t[0] / t[2]);
  EXPECT_DOUBLE_EQ(at(v, Indicator::stiffness_per_mass).value, t[2]);
  EXPECT_DOUBLE_EQ(at(v, Indicator::heating_per_power).value, t[5] / t[4]);
  EXPECT_DOUBLE_EQ(at(v, Indicator::resistance).value, 1.0 / (t[5] * 2.0));
  EXPECT_DOUBLE_EQ(at(v, Indicator::cooling).value, t[4] * 2.0);
  // Without Cth, R and λ are not determined by θ.
  const Indicators unknown = derive_indicators(t, test::window_covariance_300s());
  EXPECT_FALSE(at(unknown, Indicator::resistance).known);
  EXPECT_FALSE(at(unknown, Indicator::cooling).known);
}

TEST(Indicators, DeltaMethodSigmaMatchesTheScatter) {
  // A covariance of a few % (where the delta method's linearization is still good): the σ of
  // each indicator over 20000 draws of θ̂ agrees with the delta method within 5 %.
  const Vector6 t = test::paper_theta();
  const Matrix6 c = test::window_covariance_300s(0.01, 0.01);
  const Matrix6 l = c.llt().matrixL();
  std::mt19937_64 rng(5);
  std::normal_distribution<double> n;
  const int draws = 20000;
  std::array<double, kIndicators> sum{}, sum_sq{};
  for (int k = 0; k < draws; ++k) {
    Vector6 e;
    for (int i = 0; i < kParams; ++i) e[i] = n(rng);
    const Indicators v = derive_indicators(t + l * e, Matrix6::Zero(), 2.0);
    for (int i = 0; i < kIndicators; ++i) {
      sum[i] += v[i].value;
      sum_sq[i] += v[i].value * v[i].value;
    }
  }
  const Indicators delta = derive_indicators(t, c, 2.0);
  for (int i = 0; i < kIndicators; ++i) {
    const double mean = sum[i] / draws;
    const double sd = std::sqrt(sum_sq[i] / draws - mean * mean);
    EXPECT_NEAR(delta[i].sigma / sd, 1.0, 0.05) << kIndicatorNames[i];
  }
}

}  // namespace
}  // namespace scp::health

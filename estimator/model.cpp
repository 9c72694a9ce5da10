#include "estimator/model.hpp"

namespace scp::estimator {

PhysicalParams table1_params() noexcept {
  return PhysicalParams{
      .m = 0.1,
      .R = 1.0,
      .Cth = 0.9090,
      .lambda = 0.0540,
      .b = 124.7,
      .k = 181.3,
      .alpha1 = 0.08,
      .alpha2 = 0.01,
  };
}

Vector6 theta_from_physical(const PhysicalParams& p) noexcept {
  Vector6 theta;
  theta << p.b / p.m, p.alpha1 / p.m, p.k / p.m, p.alpha2 / p.m, p.lambda / p.Cth,
      1.0 / (p.R * p.Cth);
  return theta;
}

PhysicalParams physical_from_theta(const Vector6& theta, double m, double R) noexcept {
  const double cth = 1.0 / (R * theta(5));
  return PhysicalParams{
      .m = m,
      .R = R,
      .Cth = cth,
      .lambda = theta(4) * cth,
      .b = theta(0) * m,
      .k = theta(2) * m,
      .alpha1 = theta(1) * m,
      .alpha2 = theta(3) * m,
  };
}

}  // namespace scp::estimator

#pragma once
// Fixed-size vector and matrix types shared by the estimator. Everything is fixed-size so that the
// per-cycle path never allocates.

#include <Eigen/Core>

namespace scp::estimator {

using Vector6 = Eigen::Matrix<double, 6, 1>;
using Vector2 = Eigen::Matrix<double, 2, 1>;
using Regressor = Eigen::Matrix<double, 2, 6>;  // W of eq. (6)

}  // namespace scp::estimator

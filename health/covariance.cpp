#include "health/covariance.hpp"

#include <Eigen/Eigenvalues>
#include <cmath>

namespace scp::health {

Matrix6 positive_semidefinite(const Matrix6& c) {
  Vector6 scale = Vector6::Zero();
  for (int i = 0; i < kParams; ++i)
    if (c(i, i) > 0.0) scale[i] = std::sqrt(c(i, i));
  const Vector6 inverse = scale.unaryExpr([](double s) { return s > 0.0 ? 1.0 / s : 0.0; });
  Matrix6 unit = inverse.asDiagonal() * c * inverse.asDiagonal();
  unit = 0.5 * (unit + unit.transpose()).eval();
  const Eigen::SelfAdjointEigenSolver<Matrix6> eig(unit);
  if (eig.info() != Eigen::Success || eig.eigenvalues().minCoeff() >= 0.0) {
    return 0.5 * (c + c.transpose());
  }
  const Matrix6 repaired = eig.eigenvectors() * eig.eigenvalues().cwiseAbs().asDiagonal() *
                           eig.eigenvectors().transpose();
  return scale.asDiagonal() * repaired * scale.asDiagonal();
}

}  // namespace scp::health

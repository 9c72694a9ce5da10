#include "refine/covariance.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>

namespace scp::refine {

namespace {

int count_free(const FreeMask& free) {
  return static_cast<int>(std::count(free.begin(), free.end(), true));
}

Eigen::MatrixXd restrict(const Matrix9& m, const FreeMask& free) {
  const int n = count_free(free);
  Eigen::MatrixXd r(n, n);
  for (int i = 0, ii = 0; i < kParams; ++i) {
    if (!free[i]) continue;
    for (int j = 0, jj = 0; j < kParams; ++j) {
      if (!free[j]) continue;
      r(ii, jj++) = m(i, j);
    }
    ++ii;
  }
  return r;
}

Matrix9 expand(const Eigen::MatrixXd& r, const FreeMask& free) {
  Matrix9 m = Matrix9::Zero();
  for (int i = 0, ii = 0; i < kParams; ++i) {
    if (!free[i]) continue;
    for (int j = 0, jj = 0; j < kParams; ++j) {
      if (!free[j]) continue;
      m(i, j) = r(ii, jj++);
    }
    ++ii;
  }
  return m;
}

// N⁻¹ through the Jacobi-scaled matrix D⁻¹ N D⁻¹ (unit diagonal): its condition number is what
// the data make it, not what the units do (θ spans 0.06..1813, x0 is 1e-3 m).
bool scaled_inverse(const Eigen::MatrixXd& normal, Eigen::MatrixXd& inverse) {
  const Eigen::Index n = normal.rows();
  if (n == 0) {
    inverse.resize(0, 0);
    return true;
  }
  const Eigen::VectorXd d = normal.diagonal().cwiseMax(0.0).cwiseSqrt();
  if (!(d.minCoeff() > 0.0) || !d.allFinite()) return false;
  const Eigen::VectorXd di = d.cwiseInverse();
  const Eigen::MatrixXd scaled = di.asDiagonal() * normal * di.asDiagonal();
  Eigen::LLT<Eigen::MatrixXd> llt(scaled);
  if (llt.info() != Eigen::Success) return false;
  inverse = di.asDiagonal() * llt.solve(Eigen::MatrixXd::Identity(n, n)) * di.asDiagonal();
  return inverse.allFinite();
}

}  // namespace

bool inverse_on_free(const Matrix9& normal, const FreeMask& free, Matrix9& inverse) {
  Eigen::MatrixXd inv;
  if (!scaled_inverse(restrict(normal, free), inv)) return false;
  inverse = expand(inv, free);
  return true;
}

bool sandwich_on_free(const Matrix9& normal, const Matrix9& long_run, const FreeMask& free,
                      Matrix9& covariance) {
  Eigen::MatrixXd inv;
  if (!scaled_inverse(restrict(normal, free), inv)) return false;
  const Eigen::MatrixXd s = restrict(long_run, free);
  Eigen::MatrixXd c = inv * s * inv;
  c = 0.5 * (c + c.transpose()).eval();
  if (!c.allFinite()) return false;
  covariance = expand(c, free);
  return true;
}

int automatic_hac_lags(std::size_t samples, double rho) {
  const double n = static_cast<double>(samples);
  const double fixed = std::floor(4.0 * std::pow(n / 100.0, 2.0 / 9.0));
  double plug_in = 0.0;
  if (std::isfinite(rho)) {
    const double r = std::clamp(rho, -0.99, 0.99);
    const double alpha = 4.0 * r * r / ((1.0 - r) * (1.0 - r) * (1.0 + r) * (1.0 + r));
    plug_in = std::ceil(1.1447 * std::cbrt(alpha * n));
  }
  const double cap = std::max(1.0, std::floor(n / 10.0));
  return static_cast<int>(std::clamp(std::max(fixed, plug_in), 0.0, cap));
}

}  // namespace scp::refine

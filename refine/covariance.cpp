#include "refine/covariance.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>

namespace scp::refine {

namespace {

int count_free(const FreeMask& free) {
  return static_cast<int>(std::count(free.begin(), free.end(), true));
}

Eigen::MatrixXd restrict(const ParamMatrix& m, const FreeMask& free) {
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

ParamMatrix expand(const Eigen::MatrixXd& r, const FreeMask& free) {
  ParamMatrix m = ParamMatrix::Zero();
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

bool inverse_on_free(const ParamMatrix& normal, const FreeMask& free, ParamMatrix& inverse) {
  Eigen::MatrixXd inv;
  if (!scaled_inverse(restrict(normal, free), inv)) return false;
  inverse = expand(inv, free);
  return true;
}

bool sandwich_on_free(const ParamMatrix& normal, const ParamMatrix& long_run, const FreeMask& free,
                      ParamMatrix& covariance) {
  Eigen::MatrixXd inv;
  if (!scaled_inverse(restrict(normal, free), inv)) return false;
  const Eigen::MatrixXd s = restrict(long_run, free);
  Eigen::MatrixXd c = inv * s * inv;
  c = 0.5 * (c + c.transpose()).eval();
  if (!c.allFinite()) return false;
  covariance = expand(c, free);
  return true;
}

double chi_square_99_over_dof(double dof) {
  constexpr double kZ99 = 2.3263478740408408;
  const double v = 2.0 / (9.0 * std::max(1.0, dof));
  const double c = 1.0 - v + kZ99 * std::sqrt(v);
  return c * c * c;
}

BatchMeansCheck check_against_batch_means(ParamMatrix& covariance, const ParamMatrix& normal,
                                          std::span<const ParamVector> batch_scores,
                                          std::span<const ParamMatrix> batch_information,
                                          const FreeMask& free) {
  BatchMeansCheck out;
  const std::size_t k = batch_scores.size();
  if (k < 2 || batch_information.size() != k) return out;
  ParamMatrix inverse;
  if (!inverse_on_free(normal, free, inverse)) return out;
  ParamMatrix outer = ParamMatrix::Zero();
  for (const ParamVector& g : batch_scores) outer.noalias() += g * g.transpose();
  const ParamMatrix batch_means = inverse * outer * inverse;  // uncorrected
  // Per coordinate i, with a = N⁻¹e_i: y_b = aᵀĝ_b, ĝ_b = g_b − H_b N⁻¹ Σ_c g_c the score at θ̂.
  // Under white residuals (Cov g_b = H_b, independent) Cov(y_b, y_c) = δ_bc·aᵀH_b a −
  // u_bᵀN⁻¹u_c, u_b = H_b a: M. Σ y_b² = the batch-means variance has mean tr M and variance
  // 2·tr M² (Gaussian scores), a χ² of ν = (tr M)²/tr M² degrees of freedom scaled by tr M/ν.
  Eigen::MatrixXd m(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(k));
  Eigen::Matrix<double, kParams, Eigen::Dynamic> u(kParams, static_cast<Eigen::Index>(k));
  for (int i = 0; i < kParams; ++i) {
    const double hac = covariance(i, i);
    if (!free[i] || !(hac > 0.0)) continue;
    const ParamVector a = inverse.col(i);
    for (std::size_t b = 0; b < k; ++b)
      u.col(static_cast<Eigen::Index>(b)) = batch_information[b] * a;
    m.noalias() = -u.transpose() * inverse * u;
    for (std::size_t b = 0; b < k; ++b)
      m(static_cast<Eigen::Index>(b), static_cast<Eigen::Index>(b)) +=
          a.dot(u.col(static_cast<Eigen::Index>(b)));
    const double mean = m.trace(), spread = m.squaredNorm();
    if (!(mean > 0.0) || !(spread > 0.0)) continue;
    // Scaled to N⁻¹'s own variance, which Newey–West's estimates.
    out.ratio[i] = batch_means(i, i) * inverse(i, i) / (mean * hac);
    out.dof[i] = mean * mean / spread;
    if (std::isfinite(out.ratio[i]) && out.ratio[i] > chi_square_99_over_dof(out.dof[i]))
      out.factor[i] = std::sqrt(out.ratio[i]);
  }
  covariance = out.factor.asDiagonal() * covariance * out.factor.asDiagonal();
  return out;
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

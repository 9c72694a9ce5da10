#include "health/wald.hpp"

#include <Eigen/Cholesky>
#include <cmath>
#include <limits>

namespace scp::health {

namespace {

void test_block(int b, const Vector6& d, const Matrix6& c, const ParameterMask& free,
                BlockWald& out) {
  int idx[kParams], m = 0;
  for (int i = kBlockFirst[b]; i < kBlockEnd[b]; ++i)
    if (free[i]) idx[m++] = i;
  out.dof = m;
  if (m == 0) return;
  Eigen::MatrixXd cb(m, m);
  Eigen::VectorXd db(m);
  for (int i = 0; i < m; ++i) {
    db[i] = d[idx[i]];
    for (int j = 0; j < m; ++j) cb(i, j) = c(idx[i], idx[j]);
  }
  double stat = std::numeric_limits<double>::infinity();
  if (db.allFinite() && cb.allFinite()) {
    const Eigen::LDLT<Eigen::MatrixXd> ldlt(cb);
    if (ldlt.info() == Eigen::Success && ldlt.isPositive()) {
      const double v = db.dot(ldlt.solve(db));
      if (std::isfinite(v) && v >= 0.0) stat = v;
    }
  }
  out.statistic = stat;
  out.significant = !(stat <= out.threshold);
}

void name_moved(const WaldThresholds& th, WaldResult& r) {
  for (int b = 0; b < kBlocks; ++b) {
    if (!r.blocks[b].significant) continue;
    int largest = -1;
    for (int i = kBlockFirst[b]; i < kBlockEnd[b]; ++i) {
      const ParameterShift& p = r.parameters[i];
      if (!p.tested || std::abs(p.relative) < th.min_relative_change) continue;
      if (largest < 0 || std::abs(p.z) > std::abs(r.parameters[largest].z)) largest = i;
    }
    for (int i = kBlockFirst[b]; i < kBlockEnd[b]; ++i) {
      ParameterShift& p = r.parameters[i];
      p.moved = p.tested && std::abs(p.relative) >= th.min_relative_change &&
                (std::abs(p.z) >= th.name_z || i == largest);
    }
  }
}

}  // namespace

bool WaldResult::alarm() const noexcept {
  return first_named() >= 0;
}

int WaldResult::first_named() const noexcept {
  int best = -1;
  for (int i = 0; i < kParams; ++i)
    if (parameters[i].moved &&
        (best < 0 || std::abs(parameters[i].z) > std::abs(parameters[best].z)))
      best = i;
  return best;
}

WaldResult wald_test(const Vector6& theta, const Matrix6& covariance, const Vector6& reference,
                     const Matrix6& reference_covariance, const WaldThresholds& thresholds) {
  WaldResult r;
  const Vector6 d = theta - reference;
  const Matrix6 c = covariance + reference_covariance;
  ParameterMask free{};
  for (int i = 0; i < kParams; ++i) {
    free[i] = covariance(i, i) > 0.0 || reference_covariance(i, i) > 0.0;
    ParameterShift& p = r.parameters[i];
    p.tested = free[i];
    if (!free[i]) continue;
    p.delta = d[i];
    p.sigma = std::sqrt(c(i, i));
    p.z = d[i] / p.sigma;
    p.relative = reference[i] != 0.0 ? d[i] / std::abs(reference[i]) : 0.0;
    if (!std::isfinite(p.z)) p.z = std::numeric_limits<double>::infinity();
  }
  for (int b = 0; b < kBlocks; ++b) {
    r.blocks[b].threshold = thresholds.block[b];
    test_block(b, d, c, free, r.blocks[b]);
  }
  name_moved(thresholds, r);
  return r;
}

}  // namespace scp::health

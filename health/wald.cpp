#include "health/wald.hpp"

#include <Eigen/Cholesky>
#include <cmath>
#include <limits>

namespace scp::health {

namespace {

void test_block(int b, const Vector6& d, const Matrix6& c, const ParameterMask& free,
                BlockWald& out, std::array<ParameterShift, kParams>& parameters) {
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
      const Eigen::VectorXd score = ldlt.solve(db);
      const Eigen::MatrixXd information = ldlt.solve(Eigen::MatrixXd::Identity(m, m));
      const double v = db.dot(score);
      if (std::isfinite(v) && v >= 0.0) stat = v;
      for (int i = 0; i < m; ++i) {
        ParameterShift& p = parameters[idx[i]];
        const double info = information(i, i);
        if (!(info > 0.0)) continue;
        p.alone = score[i] / info;
        p.alone_sigma = 1.0 / std::sqrt(info);
        p.glr = score[i] * score[i] / info;
      }
    }
  }
  out.statistic = stat;
  out.significant = !(stat <= out.threshold);
}

void name_moved(const Vector6& reference, const WaldThresholds& th, WaldResult& r) {
  for (int b = 0; b < kBlocks; ++b) {
    if (!r.blocks[b].significant) continue;
    int first = -1;
    for (int i = kBlockFirst[b]; i < kBlockEnd[b]; ++i) {
      const ParameterShift& p = r.parameters[i];
      const double alone_relative = reference[i] != 0.0 ? p.alone / std::abs(reference[i]) : 0.0;
      if (!p.tested || !(std::abs(alone_relative) >= th.min_relative_change)) continue;
      if (first < 0 || p.glr > r.parameters[first].glr) first = i;
    }
    if (first < 0) continue;
    for (int i = kBlockFirst[b]; i < kBlockEnd[b]; ++i) {
      ParameterShift& p = r.parameters[i];
      p.moved = i == first || (p.tested && std::abs(p.relative) >= th.min_relative_change &&
                               std::abs(p.z) >= th.name_z);
    }
    r.first[b] = first;
  }
}

}  // namespace

bool WaldResult::alarm() const noexcept {
  return first_named() >= 0;
}

int WaldResult::first_named() const noexcept {
  int best = -1;
  for (int b = 0; b < kBlocks; ++b)
    if (first[b] >= 0 && (best < 0 || parameters[first[b]].glr > parameters[best].glr))
      best = first[b];
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
    test_block(b, d, c, free, r.blocks[b], r.parameters);
  }
  name_moved(reference, thresholds, r);
  return r;
}

}  // namespace scp::health

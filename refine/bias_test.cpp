// The Wald test of another estimate against the refined fit (refine/fit.hpp: test_against).
#include <Eigen/Cholesky>
#include <array>
#include <cmath>
#include <limits>
#include <span>
#include <vector>

#include "refine/fit.hpp"
#include "refine/parameters.hpp"

namespace scp::refine {

namespace {

// χ² quantiles at 0.999 for 1..4 degrees of freedom.
constexpr double kChi2_999[5] = {0.0, 10.828, 13.816, 16.266, 18.467};

}  // namespace

BiasTest test_against(const FitResult& fit, const Vector6& other_theta, const Vector6& other_sigma,
                      const std::array<bool, 6>& known) {
  BiasTest out;
  const std::array<std::span<const int>, 2> blocks{kMechanicalTheta, kThermalTheta};
  for (std::size_t b = 0; b < blocks.size(); ++b) {
    std::vector<int> idx;
    for (const int i : blocks[b])
      if (!known[i]) idx.push_back(i);
    const auto m = static_cast<Eigen::Index>(idx.size());
    out.threshold[b] = kChi2_999[m];
    if (m == 0) continue;
    Eigen::VectorXd d(m);
    Eigen::MatrixXd c(m, m);
    for (Eigen::Index i = 0; i < m; ++i) {
      d[i] = other_theta[idx[i]] - fit.theta[idx[i]];
      for (Eigen::Index j = 0; j < m; ++j) c(i, j) = fit.covariance(idx[i], idx[j]);
      const double s = other_sigma[idx[i]];
      c(i, i) += s * s;
    }
    double stat = std::numeric_limits<double>::infinity();
    if (d.allFinite() && c.allFinite()) {
      Eigen::LDLT<Eigen::MatrixXd> ldlt(c);
      if (ldlt.info() == Eigen::Success && ldlt.isPositive()) {
        const double v = d.dot(ldlt.solve(d));
        if (std::isfinite(v) && v >= 0.0) stat = v;
      }
    }
    out.statistic[b] = stat;
    out.biased[b] = !(stat <= out.threshold[b]);
  }
  return out;
}

}  // namespace scp::refine

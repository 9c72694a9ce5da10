#include "refine/residual_tests.hpp"

#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <vector>

#include "refine/probability.hpp"

namespace scp::refine {

namespace {

using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::VectorXd;

// A pivot below this fraction of the largest (columns scaled to unit norm) is taken as zero: far
// below any direction the data can show, far above rounding (1e-16).
constexpr double kRankThreshold = 1e-10;

// 1/‖column‖ of each column of A (0 for a zero column).
VectorXd unit_columns(const MatrixXd& a) {
  VectorXd scale(a.cols());
  for (Index j = 0; j < a.cols(); ++j) {
    const double n = a.col(j).norm();
    scale[j] = n > 0.0 ? 1.0 / n : 0.0;
  }
  return scale;
}

struct LeastSquares {
  double rss = 0.0;
  int rank = 0;
  VectorXd coefficients;  // in the columns' own units (0 for a column that dropped out)
  VectorXd residual;
};

LeastSquares least_squares(const MatrixXd& a, const VectorXd& y) {
  LeastSquares out;
  out.coefficients = VectorXd::Zero(a.cols());
  if (a.cols() == 0) {
    out.residual = y;
    out.rss = y.squaredNorm();
    return out;
  }
  const VectorXd scale = unit_columns(a);
  const MatrixXd scaled = a * scale.asDiagonal();
  Eigen::ColPivHouseholderQR<MatrixXd> qr(scaled);
  qr.setThreshold(kRankThreshold);
  // Eigen's solve() keeps every pivot above rounding, rank() only those above the threshold: the
  // fit must use the directions the degrees of freedom count, no more (a near-null direction
  // fitted to noise but not counted makes F too large).
  const Index r = qr.rank();
  out.rank = static_cast<int>(r);
  const VectorXd qty = qr.householderQ().transpose() * y;
  VectorXd c = VectorXd::Zero(a.cols());
  c.head(r) = qr.matrixQR().topLeftCorner(r, r).triangularView<Eigen::Upper>().solve(qty.head(r));
  const VectorXd coefficients = qr.colsPermutation() * c;
  out.residual = y - scaled * coefficients;
  out.rss = out.residual.squaredNorm();
  out.coefficients = scale.asDiagonal() * coefficients;
  return out;
}

// Prais–Winsten rows of an AR(1) with coefficient ρ.
MatrixXd prewhiten(const MatrixXd& a, double rho) {
  MatrixXd out(a.rows(), a.cols());
  if (a.rows() == 0) return out;
  out.row(0) = std::sqrt(1.0 - rho * rho) * a.row(0);
  for (Eigen::Index b = 1; b < a.rows(); ++b) out.row(b) = a.row(b) - rho * a.row(b - 1);
  return out;
}

double lag_one_correlation(const VectorXd& r) {
  double num = 0.0, den = 0.0;
  for (Eigen::Index b = 0; b < r.size(); ++b) {
    den += r[b] * r[b];
    if (b > 0) num += r[b] * r[b - 1];
  }
  return den > 0.0 ? num / den : 0.0;
}

struct Nested {
  LeastSquares base, full;
};

Nested nested_fits(const VectorXd& y, const MatrixXd& x, const MatrixXd& z) {
  MatrixXd xz(x.rows(), x.cols() + z.cols());
  xz << x, z;
  return {least_squares(x, y), least_squares(xz, y)};
}

struct FTest {
  bool valid = false;
  double statistic = 0.0, p_value = 1.0;
  int dof1 = 0, dof2 = 0;
};

// `lost`: degrees of freedom spent besides the regressors (1 for the estimated ρ).
FTest f_test(const Nested& n, int rows, int lost) {
  FTest t;
  t.dof1 = n.full.rank - n.base.rank;
  t.dof2 = rows - n.full.rank - lost;
  if (t.dof1 < 1 || t.dof2 < 2 || !(n.full.rss > 0.0)) return t;
  const double gain = std::max(0.0, n.base.rss - n.full.rss);
  t.statistic = (gain / t.dof1) / (n.full.rss / t.dof2);
  t.p_value = f_survival(t.statistic, t.dof1, t.dof2);
  t.valid = std::isfinite(t.statistic);
  return t;
}

// The columns of A (scaled to unit norm) that span it, in their order.
MatrixXd spanning_columns(const MatrixXd& a) {
  if (a.cols() == 0) return a;
  const MatrixXd scaled = a * unit_columns(a).asDiagonal();
  Eigen::ColPivHouseholderQR<MatrixXd> qr(scaled);
  qr.setThreshold(kRankThreshold);
  std::vector<Index> kept(static_cast<std::size_t>(qr.rank()));
  for (Index j = 0; j < qr.rank(); ++j)
    kept[static_cast<std::size_t>(j)] = qr.colsPermutation().indices()[j];
  std::sort(kept.begin(), kept.end());
  MatrixXd out(a.rows(), static_cast<Index>(kept.size()));
  for (std::size_t j = 0; j < kept.size(); ++j)
    out.col(static_cast<Index>(j)) = scaled.col(kept[j]);
  return out;
}

}  // namespace

PortmanteauResult ljung_box(const VectorXd& e, int lags) {
  PortmanteauResult out;
  const auto m = e.size();
  if (lags < 1 || m <= lags + 1) return out;
  const VectorXd d = e.array() - e.mean();
  const double c0 = d.squaredNorm();
  if (!(c0 > 0.0)) return out;
  double q = 0.0;
  for (int tau = 1; tau <= lags; ++tau) {
    const double r = d.tail(m - tau).dot(d.head(m - tau)) / c0;
    if (tau == 1) out.lag_one = r;
    q += r * r / static_cast<double>(m - tau);
  }
  out.statistic = static_cast<double>(m) * static_cast<double>(m + 2) * q;
  out.lags = lags;
  out.p_value = chi_square_survival(out.statistic, lags);
  return out;
}

VectorXd recursive_residuals(const VectorXd& y, const MatrixXd& x, const VectorXd& weights) {
  const Index m = y.size();
  const VectorXd root = weights.cwiseMax(0.0).cwiseSqrt();
  const MatrixXd a = spanning_columns(root.asDiagonal() * x);
  const Index p = a.cols();
  // The square-root information of the rows so far, [R | Qᵀy] row by row (a row of R that no
  // row has reached yet is empty): each new row is rotated into it (Givens), and what is left of
  // its y once its regressors are annihilated is its recursive residual.
  using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  RowMajor r = RowMajor::Zero(p, p + 1);
  std::vector<bool> filled(static_cast<std::size_t>(p), false);
  Eigen::RowVectorXd row(p + 1);
  VectorXd out(m);
  Index n = 0;
  for (Index b = 0; b < m; ++b) {
    row << a.row(b), root[b] * y[b];
    const double negligible = kNewDirection * row.head(p).norm();
    bool new_direction = false;
    for (Index i = 0; i < p && !new_direction; ++i) {
      if (!(std::abs(row[i]) > negligible)) continue;
      if (!filled[static_cast<std::size_t>(i)]) {
        r.row(i) = row;
        filled[static_cast<std::size_t>(i)] = true;
        new_direction = true;
        continue;
      }
      const double h = std::hypot(r(i, i), row[i]);
      const double c = r(i, i) / h, s = row[i] / h;
      for (Index j = i; j <= p; ++j) {
        const double top = r(i, j), bottom = row[j];
        r(i, j) = c * top + s * bottom;
        row[j] = c * bottom - s * top;
      }
    }
    if (!new_direction) out[n++] = row[p];
  }
  return out.head(n);
}

NestedTestResult nested_f_test(const VectorXd& y, const MatrixXd& x, const MatrixXd& z,
                               const VectorXd& weights) {
  NestedTestResult out;
  out.coefficients = VectorXd::Zero(z.cols());
  const auto m = y.size();
  if (m == 0 || z.cols() == 0) return out;
  const VectorXd root = weights.cwiseMax(0.0).cwiseSqrt();
  const VectorXd yw = root.asDiagonal() * y;
  const MatrixXd xw = root.asDiagonal() * x;
  const MatrixXd zw = root.asDiagonal() * z;
  const Nested plain = nested_fits(yw, xw, zw);
  const double raw = lag_one_correlation(plain.full.residual);
  const double rho = std::clamp(raw + (1.0 + 3.0 * raw + plain.full.rank) / static_cast<double>(m),
                                -kMaxPrewhitening, kMaxPrewhitening);
  const Nested white = nested_fits(prewhiten(yw, rho), prewhiten(xw, rho), prewhiten(zw, rho));
  out.ar1 = rho;
  if (plain.base.rss > 0.0)
    out.explained = std::max(0.0, plain.base.rss - plain.full.rss) / plain.base.rss;
  const FTest a = f_test(plain, static_cast<int>(m), 0);
  const FTest b = f_test(white, static_cast<int>(m), 1);
  if (!a.valid || !b.valid) return out;
  const FTest& binding = a.p_value >= b.p_value ? a : b;
  out.statistic = binding.statistic;
  out.dof1 = binding.dof1;
  out.dof2 = binding.dof2;
  out.p_value = binding.p_value;
  out.coefficients = white.full.coefficients.tail(z.cols());
  out.performed = true;
  return out;
}

}  // namespace scp::refine

#pragma once
// The statistical tests of refine/validation.hpp on a short series of block means (one row per
// block of the window, a few tens to a few thousand rows): a portmanteau test of whiteness and an
// F test of whether candidate regressors explain the residual beyond what the fit already does.

#include <Eigen/Core>

namespace scp::refine {

// Ljung–Box: Q = M(M+2) Σ_{τ=1..h} r(τ)²/(M−τ) ~ χ²(h) for a white series of M values, r the
// sample autocorrelation about the mean.
struct PortmanteauResult {
  double statistic = 0.0;
  int lags = 0;
  double p_value = 1.0;
  double lag_one = 0.0;  // r(1)
};
PortmanteauResult ljung_box(const Eigen::VectorXd& e, int lags);

// Recursive residuals (Brown, Durbin & Evans 1975) of y on X, rows weighted by `weights`: row
// b's error of prediction by the least-squares fit of the rows before it, standardized,
//   w_b = (y_b − x_bᵀβ̂_{b−1}) / √(1 + x_bᵀ(X_{b−1}ᵀX_{b−1})⁻¹x_b),
// in the rows' order; a row that brings a direction of X the rows before it lack has none (M −
// rank X of them). For white Gaussian errors they are independent N(0, σ²) whatever X is, where
// the residuals of the fit are not: a fit with parameters of local reach (a phase per voltage
// switch, each explaining a few blocks after its switch) leaves those blocks' residuals
// negatively correlated by construction, which Ljung–Box on them reads as colour (and so does
// Breusch–Godfrey's test, whose F holds only for few parameters per row). Coloured errors stay
// coloured in w: Ljung–Box on w tests whiteness beyond what the fit explains.
Eigen::VectorXd recursive_residuals(const Eigen::VectorXd& y, const Eigen::MatrixXd& x,
                                    const Eigen::VectorXd& weights);

// A regressor smaller than this fraction of its row's norm, once the rows before it are rotated
// out, is rounding: not a direction of its own.
inline constexpr double kNewDirection = 1e-12;

// Does Z explain y beyond X? Weighted least squares of y on [X, Z] against y on X alone, rows
// weighted by `weights` (block means of unequal sample counts; all ones for equal blocks), and the
// F statistic of the decrease in the residual sum of squares:
//   F = ((RSS_X − RSS_XZ)/q) / (RSS_XZ/(M − r)),  q = rank[X Z] − rank X, r = rank[X Z].
// Under white Gaussian y − Xβ, F ~ F(q, M − r): exact however collinear the columns (a column, or
// a direction of Z, already in the span of X drops out of q).
// Colour in the residual (errors slower than a block: a drift of the sensor's mount) would read as
// a dependence on any slow regressor. The test is therefore also run on rows prewhitened by the
// AR(1) coefficient of the full residual y − Xβ − Zγ (Cochrane–Orcutt, Prais–Winsten rows: row 1
// scaled by √(1 − ρ²), row b minus ρ times row b − 1; one degree of freedom fewer), and reports the
// larger of the two p-values. ρ̂ is corrected for its small-sample bias, (1 + 3ρ̂ + r)/M (Hurwicz's
// term, and r for regressors as slow as these, which absorb the residual's own slow part).
// Measured on 140 rows of smooth regressors (tests/refine/test_residual_tests.cpp and
// docs/validation.md): the plain test alone is exact on white noise and rejects 60 % at a 0.2 %
// level under AR(1) 0.7; the prewhitened alone rejects 0.9 % on white noise at 0.2 %; the larger p
// keeps white noise at or below the level and AR(1) 0.7 at 2 %. The full residual is white when Z
// explains what X left, so the right candidate keeps its power; a candidate that leaves structure
// behind has it read as colour and loses some: a specificity the naming of a term relies on.
struct NestedTestResult {
  bool performed = false;  // q ≥ 1 and M − r − 1 ≥ 2
  // F, its degrees of freedom (q, M − r or M − r − 1) and p-value: the run, plain or prewhitened,
  // whose p-value is the larger.
  double statistic = 0.0;
  int dof1 = 0;
  int dof2 = 0;
  double p_value = 1.0;
  double ar1 = 0.0;  // the bias-corrected ρ of the prewhitening
  // (RSS_X − RSS_XZ)/RSS_X of the first run (not prewhitened): the share of what X left that Z
  // explains. Which of several candidates explains most is what names a missing term.
  double explained = 0.0;
  // The prewhitened (feasible GLS) estimate of Z's coefficients: each candidate's effect in its
  // units.
  Eigen::VectorXd coefficients;
};
NestedTestResult nested_f_test(const Eigen::VectorXd& y, const Eigen::MatrixXd& x,
                               const Eigen::MatrixXd& z, const Eigen::VectorXd& weights);

// Largest |ρ| the prewhitening uses: a residual closer to a random walk is prewhitened as one
// that nearly is (differencing), not extrapolated beyond.
inline constexpr double kMaxPrewhitening = 0.99;

}  // namespace scp::refine

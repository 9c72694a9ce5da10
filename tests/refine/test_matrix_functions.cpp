// exp, φ1, φ2 of 2×2 matrices against an independent reference: the Taylor series
// φk(X) = Σ X^j/(j+k)! in long double on the balanced matrix (D M D⁻¹, D = diag(1, s), so that a
// companion matrix with entries 1e-3 and 4e3 does not cost the series its digits), scaled by 2^-n
// to norm ≤ 1/4 and squared back with e^{2X} = (e^X)², φ1(2X) = φ1(X)(e^X + I)/2,
// φ2(2X) = (φ2(X) + e^X φ2(X) + φ1(X))/4.
#include <gtest/gtest.h>

#include <array>
#include <cmath>

#include "refine/matrix_functions.hpp"

namespace scp::refine {
namespace {

using Matrix2L = Eigen::Matrix<long double, 2, 2>;

ExpPhi reference(const Matrix2& m) {
  const double s = m(0, 1) != 0.0 && m(1, 0) != 0.0 ? std::sqrt(std::abs(m(1, 0) / m(0, 1))) : 1.0;
  Matrix2L x;
  x << m(0, 0), m(0, 1) / s, m(1, 0) * s, m(1, 1);
  int squarings = 0;
  while (x.cwiseAbs().rowwise().sum().maxCoeff() > 0.25L) {
    x /= 2.0L;
    ++squarings;
  }
  const Matrix2L id = Matrix2L::Identity();
  Matrix2L f[3] = {Matrix2L::Zero(), Matrix2L::Zero(), Matrix2L::Zero()};
  for (int k = 0; k < 3; ++k) {
    Matrix2L term = id;
    long double fact = 1.0L;
    for (int i = 2; i <= k; ++i) fact *= i;
    term /= fact;  // X^0/k!
    for (int j = 0; j < 40; ++j) {
      f[k] += term;
      term = term * x / static_cast<long double>(j + k + 1);
    }
  }
  for (int i = 0; i < squarings; ++i) {
    const Matrix2L e = f[0];
    f[2] = (f[2] + e * f[2] + f[1]) / 4.0L;
    f[1] = f[1] * (e + id) / 2.0L;
    f[0] = e * e;
  }
  ExpPhi out;
  Matrix2* o[3] = {&out.exp, &out.phi1, &out.phi2};
  for (int k = 0; k < 3; ++k) {
    *o[k] << static_cast<double>(f[k](0, 0)), static_cast<double>(f[k](0, 1) * s),
        static_cast<double>(f[k](1, 0) / s), static_cast<double>(f[k](1, 1));
  }
  return out;
}

void expect_close(const Matrix2& m, double tol, const char* what) {
  const ExpPhi got = exp_phi(m), want = reference(m);
  const Matrix2* g[3] = {&got.exp, &got.phi1, &got.phi2};
  const Matrix2* w[3] = {&want.exp, &want.phi1, &want.phi2};
  for (int k = 0; k < 3; ++k) {
    const double err = (*g[k] - *w[k]).norm() / std::max(w[k]->norm(), 1e-300);
    EXPECT_LT(err, tol) << what << ", function " << k << "\n" << *g[k] << "\nvs\n" << *w[k];
  }
}

// One 1 ms step of the companion matrix [[0, 1], [−k, −c]].
Matrix2 companion(double k, double c, double tau = 1e-3) {
  Matrix2 m;
  m << 0.0, tau, -k * tau, -c * tau;
  return m;
}

TEST(MatrixFunctions, OverdampedStiffPaperActuator) {
  expect_close(companion(1813.0, 1247.0 + 0.8 * 50.0), 1e-13, "paper, 1 ms");
  expect_close(companion(1813.0, 1247.0, 10.0), 1e-12, "paper, a 10 s gap");
}

TEST(MatrixFunctions, UnderdampedComplexPair) {
  expect_close(companion(20000.0, 100.0), 1e-13, "underdamped, 1 ms");
  expect_close(companion(4e6, 10.0), 1e-12, "lightly damped, |z| > 1");
}

// The series' term count steps at |z| = 1/32, 1/4, 1/2 and 1 (the eigenvalues' modulus is
// τ·√k): each count is tried at the top of its disc, where its truncation is largest.
TEST(MatrixFunctions, ComplexPairAtEachSeriesLength) {
  const double k = 20000.0;
  for (double radius : {1.0 / 32.0, 0.25, 0.5, 1.0}) {
    for (double fraction : {0.999999, 0.6}) {
      const double tau = radius * fraction / std::sqrt(k);
      expect_close(companion(k, 100.0, tau), 1e-13, "underdamped, |z| below a series step");
      expect_close(companion(k, 1.0, tau), 1e-13, "nearly undamped, |z| below a series step");
    }
  }
}

TEST(MatrixFunctions, RepeatedAndNearlyRepeatedEigenvalues) {
  expect_close(companion(250000.0, 1000.0), 1e-13, "critically damped");
  expect_close(companion(250000.0 * (1 + 1e-9), 1000.0), 1e-13, "δ ≈ 1e-5");
  expect_close(companion(250000.0 * (1 + 1e-5), 1000.0), 1e-12, "δ ≈ 1.6e-3, divided difference");
  Matrix2 jordan;
  jordan << -0.3, 1.0, 0.0, -0.3;
  expect_close(jordan, 1e-14, "Jordan block");
}

TEST(MatrixFunctions, ZeroAndGeneralMatrices) {
  expect_close(Matrix2::Zero(), 1e-15, "zero");
  Matrix2 m;
  m << 0.3, -1.7, 0.4, -2.2;
  expect_close(m, 1e-13, "general real pair");
  m << 0.1, -2.0, 3.0, 0.2;
  expect_close(m, 1e-13, "general complex pair");
}

TEST(MatrixFunctions, ScalarPhiNearZero) {
  for (double z : {-1e-12, -6e-5, -0.3, -0.5, -0.7, -3.0, 2.0}) {
    const Phi12 p = phi12(z);
    // Long-double closed forms as the reference (cancellation is 1e-19 there).
    const long double zl = z;
    const long double p1 = std::expm1(zl) / zl;
    const long double p2 = (p1 - 1.0L) / zl;
    EXPECT_NEAR(p.phi1, static_cast<double>(p1), 1e-15) << z;
    if (std::abs(z) > 1e-6) {
      EXPECT_NEAR(p.phi2, static_cast<double>(p2), 2e-15) << z;
    }
  }
  EXPECT_NEAR(phi12(-1e-12).phi2, 0.5 - 1e-12 / 6.0, 1e-16);
}

TEST(MatrixFunctions, ScalarPhiFunctionsZeroToFive) {
  // φ0..φ5 (the thermal block's coefficients) against the long-double closed forms
  // φ_{k+1} = (φ_k − 1/k!)/z, whose cancellation costs at most ~1e-19·5!/|z|^5 here.
  for (double z : {-6e-5, -1e-3, -0.3, -0.9, -1.5, -3.0, 2.0}) {
    const std::array<double, 6> p = phi_functions(z);
    const long double zl = z;
    long double want = std::exp(zl), inv_fact = 1.0L;
    for (int k = 0; k < 6; ++k) {
      if (std::abs(z) > 0.2 || k < 2) {
        EXPECT_NEAR(p[static_cast<std::size_t>(k)], static_cast<double>(want),
                    3e-15 * std::abs(static_cast<double>(want)))
            << "z " << z << ", k " << k;
      }
      want = (want - inv_fact) / zl;
      inv_fact /= (k + 1);
    }
  }
  // Near 0 against the series' leading terms: φk(z) = 1/k! + z/(k+1)! + O(z²).
  const std::array<double, 6> p = phi_functions(-1e-9);
  double inv_fact = 1.0;
  for (int k = 0; k < 6; ++k) {
    EXPECT_NEAR(p[static_cast<std::size_t>(k)], inv_fact - 1e-9 * inv_fact / (k + 1), 1e-17) << k;
    inv_fact /= (k + 1);
  }
}

}  // namespace
}  // namespace scp::refine

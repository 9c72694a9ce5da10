#pragma once
// Eigen::LDLT<Matrix<double, N, N>>(a).solve(b) for the estimator's 4×4 and 2×2 blocks, written
// out for fixed N and giving the same bits.
//
// Why not Eigen's: its LDLᵀ is generic in the size. The factorization walks dynamic-size blocks
// with run-time loops, computes an L1 norm for rcond() that nobody reads, and tracks the sign of
// the matrix; on the 4×4 block that was a large share of one estimator update (callgrind;
// docs/numerics.md, "Figures behind the code comments"). Why not a plain Cholesky: R is
// ill-conditioned (PAPER-NOTES), so a different factorization changes the solve by cond(R)·eps, and
// the trajectory of θ̂ with it. This one repeats Eigen 3.4's arithmetic operation for operation (the
// same diagonal pivoting, the same order of every sum, the same zero-pivot rule), so θ̂ stays
// bit-identical; tests/estimator/test_small_ldlt.cpp checks that against Eigen on random and
// ill-conditioned matrices. Only the lower triangle of `a` is read, as in Eigen.
//
// Sums whose order matters (the operation order of Eigen 3.4 at -O3 without FMA):
// - factorization: A(k,k) − Σ_j L(k,j)·D(j)·L(k,j) and A(i,k) − Σ_j L(i,j)·(D(j)·L(k,j)), summed
//   left to right, then subtracted;
// - forward solve with L (rows, stride N): the fixed-size reduction of Eigen's unroller, which
//   halves: x0 + (x1 + x2) for three terms;
// - backward solve with Lᵀ (contiguous): one SSE2 packet then the rest: (x0 + x1) + x2.

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

namespace scp::estimator {

template <int N>
Eigen::Matrix<double, N, 1> small_ldlt_solve(const Eigen::Matrix<double, N, N>& a,
                                             const Eigen::Matrix<double, N, 1>& b) noexcept {
  static_assert(N == 2 || N == 4, "written out and checked for the estimator's blocks only");
  // Eigen's factorization is left-looking: at step k the trailing diagonal still holds A's own
  // entries, so its pivot order (largest |A_ii| first, the first of equals in the current
  // arrangement) is known before any arithmetic. Permuting first and factoring P·A·Pᵀ without
  // pivoting does the same operations on the same numbers, with every index known at compile
  // time (the compiler keeps the matrix in registers).
  // Every index below is a compile-time constant after unrolling, the permutation included
  // (conditional swaps of registers): indexing stack arrays with run-time indices cost more than
  // the arithmetic (store-to-load forwarding stalls, measured).
  int order[N];
  for (int i = 0; i < N; ++i) order[i] = i;
  // |A_ii| read straight from `a` each time: a local array of them was vectorized by GCC into
  // 16-byte stores read back as 8-byte halves, a store-forwarding stall (measured, perf).
  const auto magnitude = [&a](int i) noexcept { return std::abs(a(i, i)); };
  for (int k = 0; k < N - 1; ++k) {
    int p = k;
    double biggest = magnitude(order[k]);
    for (int i = k + 1; i < N; ++i) {
      const double v = magnitude(order[i]);
      if (v > biggest) {
        biggest = v;
        p = i;
      }
    }
    for (int i = k + 1; i < N; ++i) {
      if (p == i) std::swap(order[k], order[i]);
    }
  }
  const double* lower = a.data();  // column-major: (r, c) at c·N + r
  double m[N][N];  // m[i][j], i ≥ j: P·A·Pᵀ, overwritten by L below the diagonal and D on it
  for (int j = 0; j < N; ++j) {
    for (int i = j; i < N; ++i) {
      // the lower triangle of A, as Eigen reads it
      m[i][j] = lower[std::min(order[i], order[j]) * N + std::max(order[i], order[j])];
    }
  }
  for (int k = 0; k < N; ++k) {
    if (k > 0) {
      double temp[N];
      for (int j = 0; j < k; ++j) temp[j] = m[j][j] * m[k][j];
      double s = m[k][0] * temp[0];
      for (int j = 1; j < k; ++j) s += m[k][j] * temp[j];
      m[k][k] -= s;
      for (int i = k + 1; i < N; ++i) {
        double t = m[i][0] * temp[0];
        for (int j = 1; j < k; ++j) t += m[i][j] * temp[j];
        m[i][k] -= t;
      }
    }
    // A zero pivot (exactly 0: R is positive definite, so only after underflow) leaves its
    // column as it is, like Eigen; the solve below then zeroes that component.
    const double d = m[k][k];
    if (std::abs(d) > 0.0) {
      for (int i = k + 1; i < N; ++i) m[i][k] /= d;
    }
  }

  double x[N];
  for (int i = 0; i < N; ++i) x[i] = b(order[i]);
  // x ← L⁻¹ x
  if constexpr (N == 2) {
    x[1] -= m[1][0] * x[0];
  } else {
    x[1] -= m[1][0] * x[0];
    x[2] -= m[2][0] * x[0] + m[2][1] * x[1];
    x[3] -= m[3][0] * x[0] + (m[3][1] * x[1] + m[3][2] * x[2]);
  }
  // x ← D⁻¹ x, the pseudo-inverse for a pivot at or below the smallest normal double
  for (int i = 0; i < N; ++i) {
    if (std::abs(m[i][i]) > std::numeric_limits<double>::min()) {
      x[i] /= m[i][i];
    } else {
      x[i] = 0.0;
    }
  }
  // x ← L⁻ᵀ x
  if constexpr (N == 2) {
    x[0] -= m[1][0] * x[1];
  } else {
    x[2] -= m[3][2] * x[3];
    x[1] -= m[2][1] * x[2] + m[3][1] * x[3];
    x[0] -= (m[1][0] * x[1] + m[2][0] * x[2]) + m[3][0] * x[3];
  }
  Eigen::Matrix<double, N, 1> out;
  for (int j = 0; j < N; ++j) {
    double v = x[0];
    for (int i = 1; i < N; ++i) v = order[i] == j ? x[i] : v;
    out(j) = v;
  }
  return out;
}

}  // namespace scp::estimator

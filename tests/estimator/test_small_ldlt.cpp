// small_ldlt_solve must give Eigen's LDLT bits exactly: the estimator's θ̂ trajectory depends on
// every rounding of the solve (R is ill-conditioned), and its tests and the paper-reproduction
// figures were measured with Eigen's LDLT.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/QR>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>

#include "estimator/small_ldlt.hpp"

namespace scp::estimator {
namespace {

template <int N>
using Mat = Eigen::Matrix<double, N, N>;
template <int N>
using Vec = Eigen::Matrix<double, N, 1>;

template <int N>
bool same_bits(const Vec<N>& a, const Vec<N>& b) {
  return std::memcmp(a.data(), b.data(), sizeof(double) * N) == 0;
}

// Q·diag(λ)·Qᵀ with eigenvalues spread over `decades` and a random orientation, then scaled per
// row/column like the estimator's unscaled θ coordinates (entries from 1e-3 to 1e3).
template <int N>
Mat<N> random_spd(std::mt19937_64& rng, double decades, bool graded) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Mat<N> g;
  for (int i = 0; i < N; ++i) {
    for (int j = 0; j < N; ++j) g(i, j) = u(rng);
  }
  const Eigen::HouseholderQR<Mat<N>> qr(g);
  const Mat<N> q = qr.householderQ();
  Vec<N> lambda;
  for (int i = 0; i < N; ++i) lambda(i) = std::pow(10.0, decades * (0.5 * u(rng) + 0.5));
  Mat<N> a = q * lambda.asDiagonal() * q.transpose();
  if (graded) {
    Vec<N> d;
    for (int i = 0; i < N; ++i) d(i) = std::pow(10.0, 3.0 * u(rng));
    a = d.asDiagonal() * a * d.asDiagonal();
  }
  return 0.5 * (a + a.transpose());
}

template <int N>
int mismatches(std::uint64_t seed, int trials) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int bad = 0;
  for (int t = 0; t < trials; ++t) {
    const double decades = 16.0 * (t % 5) / 4.0;  // condition numbers 1 … 1e16
    const Mat<N> a = random_spd<N>(rng, decades, t % 2 == 1);
    Vec<N> b;
    for (int i = 0; i < N; ++i) b(i) = u(rng) * std::pow(10.0, 3.0 * u(rng));
    const Vec<N> expected = Eigen::LDLT<Mat<N>>(a).solve(b);
    const Vec<N> got = small_ldlt_solve<N>(a, b);
    if (!same_bits<N>(expected, got)) ++bad;
  }
  return bad;
}

TEST(SmallLdlt, FourByFourMatchesEigenBitForBit) {
  EXPECT_EQ(mismatches<4>(1, 200000), 0);
}

TEST(SmallLdlt, TwoByTwoMatchesEigenBitForBit) {
  EXPECT_EQ(mismatches<2>(2, 200000), 0);
}

// The estimator's R + wᵀw: information matrix plus a rank-one term, every pivot order.
TEST(SmallLdlt, RankOneUpdatesAndEveryPivotOrderMatchEigen) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int bad = 0;
  for (int t = 0; t < 50000; ++t) {
    Mat<4> r = random_spd<4>(rng, 12.0, true);
    Vec<4> w;
    for (int i = 0; i < 4; ++i) w(i) = u(rng) * std::pow(10.0, 2.0 * u(rng));
    r += w * w.transpose();
    const Vec<4> b = w * u(rng);
    if (!same_bits<4>(Eigen::LDLT<Mat<4>>(r).solve(b), small_ldlt_solve<4>(r, b))) ++bad;
  }
  EXPECT_EQ(bad, 0);
}

// Equal diagonal entries (e.g. R(0) = I/p0): the pivot is the first of equals in the current
// arrangement, as Eigen's maxCoeff picks it.
TEST(SmallLdlt, TiesInTheDiagonalPivotLikeEigen) {
  std::mt19937_64 rng(4);
  std::uniform_int_distribution<int> level(1, 3);
  std::uniform_real_distribution<double> u(-0.3, 0.3);
  int bad = 0;
  for (int t = 0; t < 20000; ++t) {
    Mat<4> a;
    for (int i = 0; i < 4; ++i) {
      a(i, i) = level(rng);
      for (int j = 0; j < i; ++j) a(i, j) = a(j, i) = u(rng);
    }
    const Vec<4> b = Vec<4>::Random();
    if (!same_bits<4>(Eigen::LDLT<Mat<4>>(a).solve(b), small_ldlt_solve<4>(a, b))) ++bad;
    const Mat<2> a2 = a.topLeftCorner<2, 2>();
    const Vec<2> b2 = b.head<2>();
    if (!same_bits<2>(Eigen::LDLT<Mat<2>>(a2).solve(b2), small_ldlt_solve<2>(a2, b2))) ++bad;
  }
  EXPECT_EQ(bad, 0);
}

// Semidefinite and degenerate blocks (a known parameter's zero column, a zero matrix): Eigen's
// pseudo-inverse rule for a zero pivot.
TEST(SmallLdlt, SingularMatricesFollowEigensZeroPivotRule) {
  Mat<4> a = Mat<4>::Zero();
  const Vec<4> b(1.0, -2.0, 3.0, 4.0);
  EXPECT_TRUE(same_bits<4>(Eigen::LDLT<Mat<4>>(a).solve(b), small_ldlt_solve<4>(a, b)));
  a(0, 0) = 2.0;
  a(2, 2) = 5.0;
  a(0, 2) = a(2, 0) = 1.0;
  EXPECT_TRUE(same_bits<4>(Eigen::LDLT<Mat<4>>(a).solve(b), small_ldlt_solve<4>(a, b)));
  const Vec<4> v(1.0, 2.0, 3.0, 4.0);
  a = v * v.transpose();  // rank one
  EXPECT_TRUE(same_bits<4>(Eigen::LDLT<Mat<4>>(a).solve(b), small_ldlt_solve<4>(a, b)));
  Mat<2> z = Mat<2>::Zero();
  z(1, 1) = 3.0;
  const Vec<2> c(1.0, 2.0);
  EXPECT_TRUE(same_bits<2>(Eigen::LDLT<Mat<2>>(z).solve(c), small_ldlt_solve<2>(z, c)));
}

}  // namespace
}  // namespace scp::estimator

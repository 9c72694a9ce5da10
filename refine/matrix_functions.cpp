#include "refine/matrix_functions.hpp"

#include <array>
#include <cmath>
#include <complex>

namespace scp::refine {

namespace {

using Complex = std::complex<double>;

// Below this |z| the φ-functions come from their power series Σ z^j/(j+k)!: 20 terms reach the
// last bit for |z| ≤ 1, while the closed forms lose up to log10(1/|z|) digits to cancellation.
constexpr double kSeriesRadius = 1.0;
constexpr int kSeriesTerms = 20;

// 1/n for the series' terms: a product where a quotient would cost ~5 times as much and sit on
// the loop's dependency chain (the terms differ from the quotients' by an ulp at most).
constexpr std::array<double, kSeriesTerms + 8> kInverse = [] {
  std::array<double, kSeriesTerms + 8> inv{};
  for (std::size_t n = 1; n < inv.size(); ++n) inv[n] = 1.0 / static_cast<double>(n);
  return inv;
}();
// 1/k! for k = 0..5.
constexpr std::array<double, 6> kInverseFactorial{1.0,       1.0,        0.5,
                                                  1.0 / 6.0, 1.0 / 24.0, 1.0 / 120.0};

// Up to this |z| the first eight terms of φ2's series reach the last bit: the ninth,
// |z|⁸/10!, is below 1e-18 of φ2 ≥ 0.49.
constexpr double kShortSeriesRadius = 1.0 / 32.0;
// 1/(j+2)! for j = 0..17: the most terms of φ2's series phi2_series_terms() asks for.
constexpr std::array<double, 18> kPhi2Series = [] {
  std::array<double, 18> c{};
  double f = 2.0;
  for (std::size_t j = 0; j < c.size(); ++j) {
    c[j] = 1.0 / f;
    f *= static_cast<double>(j + 3);
  }
  return c;
}();

// Whether a series whose sum is `sum` has converged once its next term is `term`: that and every
// later term are below 1e-17 of it, under half an ulp.
bool converged(double term, double sum) noexcept {
  return std::abs(term) < 1e-17 * std::abs(sum);
}

// How many terms of φ2's series Σ z^j/(j+2)! reach the last bit for |z|² ≤ `norm`: the first
// term left out, |z|^n/(n+2)!, is below 1e-17 of |φ2| ≥ 0.36 on |z| ≤ 1. The fewest the step's
// |z| needs, where one count for the whole disc would spend 18 on a 1 ms step of ωn = 141 rad/s.
int phi2_series_terms(double norm) noexcept {
  if (norm <= kShortSeriesRadius * kShortSeriesRadius) return 8;
  if (norm <= 1.0 / 16.0) return 12;  // |z| ≤ 1/4
  if (norm <= 1.0 / 4.0) return 14;   // |z| ≤ 1/2
  return 18;
}

// f(M) = g0·I + g1·N with N = M − cI, N² = δ²I: such pairs multiply as
// (a0 + a1 N)(b0 + b1 N) = (a0 b0 + δ² a1 b1) + (a0 b1 + a1 b0) N, so a series in M runs on two
// doubles, with no eigenvalue, square root or quotient (for δ² < 0 these are the complex numbers
// a0 + i·ω·a1, ω² = −δ²).
struct Pair {
  double g0, g1;
};

// The (g0, g1) pairs of the header for f = exp, φ1, φ2.
struct G {
  Pair f[3];
};

struct PairAlgebra {
  double delta2;

  Pair times(Pair a, Pair b) const noexcept {
    return {a.g0 * b.g0 + delta2 * a.g1 * b.g1, a.g0 * b.g1 + a.g1 * b.g0};
  }
  Pair plus_times(Pair a, Pair b, Pair z) const noexcept {  // a + b·z
    return {a.g0 + b.g0 * z.g0 + delta2 * b.g1 * z.g1, a.g1 + b.g0 * z.g1 + b.g1 * z.g0};
  }
  Pair linear(double c0, double c1, Pair z) const noexcept {  // c0·I + c1·z
    return {c0 + c1 * z.g0, c1 * z.g1};
  }
};

// The same operations on real numbers: the scalar φ2 of a real z (phi12).
struct RealAlgebra {
  double times(double a, double b) const noexcept { return a * b; }
  double plus_times(double a, double b, double z) const noexcept { return a + b * z; }
  double linear(double c0, double c1, double z) const noexcept { return c0 + c1 * z; }
};

// One level of Estrin's order: level[j] = level[2j] + level[2j+1]·power over the first `Width`
// entries, then the next level with power². A template of its width, so that every loop has a
// trip count the compiler sees and unrolls, and the entries stay in registers.
template <std::size_t Width, class Algebra, class Value, std::size_t Size>
Value fold(const Algebra& algebra, std::array<Value, Size>& level, Value power) noexcept {
  if constexpr (Width == 1) {
    return level[0];
  } else {
    for (std::size_t j = 0; j < Width / 2; ++j) {
      level[j] = algebra.plus_times(level[2 * j], level[2 * j + 1], power);
    }
    if constexpr (Width % 2 == 1) level[Width / 2] = level[Width - 1];
    return fold<(Width + 1) / 2>(algebra, level, algebra.times(power, power));
  }
}

// Σ_{j<N} m^j/(j+2)! in Estrin's order: pairs c_{2j} + c_{2j+1}·m, then pairs of those times
// m², m⁴, ...; a chain of ⌈log2 N⌉ products where Horner's order waits on N − 1 in turn. On
// real numbers (RealAlgebra) or on the pairs of a 2×2 matrix (PairAlgebra).
template <std::size_t N, class Algebra, class Value>
Value phi2_series(const Algebra& algebra, Value m) noexcept {
  std::array<Value, (N + 1) / 2> level{};
  for (std::size_t j = 0; j < level.size(); ++j) {
    const double odd = 2 * j + 1 < N ? kPhi2Series[2 * j + 1] : 0.0;
    level[j] = algebra.linear(kPhi2Series[2 * j], odd, m);
  }
  return fold<(N + 1) / 2>(algebra, level, algebra.times(m, m));
}

// The (g0, g1) of exp, φ1, φ2 for a complex pair c ± iω inside the unit disc (c² − δ² = |c ± iω|²
// < 1): φ2 from its series, then φ1 = I + M·φ2 and e^M = I + M·φ1, no transcendental call.
G series_coefficients(double c, double delta2) noexcept {
  const PairAlgebra algebra{delta2};
  const Pair m{c, 1.0};  // M = c·I + 1·N
  G g;
  Pair* f = g.f;
  switch (phi2_series_terms(c * c - delta2)) {
    case 8:
      f[2] = phi2_series<8>(algebra, m);
      break;
    case 12:
      f[2] = phi2_series<12>(algebra, m);
      break;
    case 14:
      f[2] = phi2_series<14>(algebra, m);
      break;
    default:
      f[2] = phi2_series<18>(algebra, m);
      break;
  }
  f[1] = algebra.plus_times({1.0, 0.0}, f[2], m);
  f[0] = algebra.plus_times({1.0, 0.0}, f[1], m);
  return g;
}

// φ1 and φ2 at complex z with |z| ≥ 1, given e = e^z: 1/z as z̄/|z|² (nothing to overflow), not
// std::complex's division, whose library call guards against infinities that cannot occur here
// and cost as much as the exponential.
std::array<Complex, 2> phi12_of(Complex z, Complex e) noexcept {
  const Complex inverse = std::conj(z) / std::norm(z);
  const Complex p1 = (e - 1.0) * inverse;
  return {p1, (p1 - 1.0) * inverse};
}

// e^z, φ1(z), φ2(z) at real z, one transcendental call: near 0 the series and e^z = 1 + z·φ1;
// beyond |z| = 0.5, e^z and φ1 = (e^z − 1)/z, whose subtraction loses at most an ulp there
// (|e^z − 1| ≥ 0.39), where expm1 beside exp would cost a second call.
std::array<double, 3> phis_of_real(double z) noexcept {
  if (std::abs(z) < 0.5) {
    const Phi12 p = phi12(z);
    return {1.0 + z * p.phi1, p.phi1, p.phi2};
  }
  const double e = std::exp(z);
  const double inverse = 1.0 / z;  // beside the exponential, off the chain that waits for it
  const double p1 = (e - 1.0) * inverse;
  return {e, p1, (p1 - 1.0) * inverse};
}

// φ0..φ5 at real z (the thermal block's coefficients, the derivatives in the repeated-eigenvalue
// branch).
std::array<double, 6> phis(double z) noexcept {
  std::array<double, 6> p{};
  if (std::abs(z) < kSeriesRadius) {
    // φ5 from its series Σ z^j/(j+5)!, then downward φ_k = 1/k! + z·φ_{k+1}: stable for |z| < 1
    // (an error in φ_{k+1} reaches φ_k times |z|), one series instead of six.
    double term = kInverseFactorial[5], sum = 0.0;
    for (std::size_t j = 0; j < kSeriesTerms; ++j) {
      sum += term;
      term *= z * kInverse[j + 6];
      if (converged(term, sum)) break;
    }
    p[5] = sum;
    for (std::size_t k = 5; k-- > 0;) p[k] = kInverseFactorial[k] + z * p[k + 1];
    return p;
  }
  // Upward recurrence φ_{k+1} = (φ_k − 1/k!)/z: stable for |z| ≥ 1 (errors shrink by 1/|z|).
  p[0] = std::exp(z);
  for (std::size_t k = 0; k < 5; ++k) p[k + 1] = (p[k] - kInverseFactorial[k]) / z;
  return p;
}

// Below this |δ| the divided difference (f(c+δ) − f(c−δ))/(2δ) loses more than ~1e-13 to
// cancellation; the Taylor series in δ² truncated after δ² is then accurate to ~|δ|⁴/24 < 1e-13.
constexpr double kRepeatedDelta = 1e-3;

G coefficients(double c, double delta2, double det) noexcept {
  G g{};
  if (std::abs(delta2) < kRepeatedDelta * kRepeatedDelta) {
    // f(c ± δ) = Σ f^(n)(c)·(±δ)^n/n!, so g0 = f + f''·δ²/2 and g1 = f' + f'''·δ²/6 up to O(δ⁴);
    // the derivatives of φk are sums of φk, φk+1, ... (φk' = φk − k·φ_{k+1}).
    const auto p = phis(c);
    for (int k = 0; k < 3; ++k) {
      const double a = k, a1 = k * (k + 1.0), a2 = k * (k + 1.0) * (k + 2.0);
      const double d1 = p[k] - a * p[k + 1];
      const double d2 = p[k] - 2.0 * a * p[k + 1] + a1 * p[k + 2];
      const double d3 = p[k] - 3.0 * a * p[k + 1] + 3.0 * a1 * p[k + 2] - a2 * p[k + 3];
      g.f[k].g0 = p[k] + 0.5 * d2 * delta2;
      g.f[k].g1 = d1 + d3 * delta2 / 6.0;
    }
    return g;
  }
  if (delta2 > 0.0) {
    const double delta = std::sqrt(delta2);
    // The eigenvalue nearer zero comes from Vieta (λ+·λ− = det M) rather than c ± δ, which
    // cancels for a stiff pair (the paper's slow pole is 1e-3 of the fast one).
    double lp = c + delta, lm = c - delta;
    if (c >= 0.0) {
      lm = lp != 0.0 ? det / lp : lm;
    } else {
      lp = det / lm;
    }
    const auto fp = phis_of_real(lp), fm = phis_of_real(lm);
    const double inverse_gap = 0.5 / delta;  // λ+ − λ− = 2δ
    for (std::size_t k = 0; k < 3; ++k) {
      g.f[k].g0 = 0.5 * (fp[k] + fm[k]);
      g.f[k].g1 = (fp[k] - fm[k]) * inverse_gap;
    }
    return g;
  }
  if (c * c - delta2 < kSeriesRadius * kSeriesRadius) {
    return series_coefficients(c, delta2);
  }
  const double omega = std::sqrt(-delta2);
  const Complex z(c, omega);
  const Complex e = std::polar(std::exp(c), omega);  // finite z: no need of cexp's special cases
  const auto f = phi12_of(z, e);
  const Complex v[3] = {e, f[0], f[1]};
  for (int k = 0; k < 3; ++k) {
    g.f[k].g0 = v[k].real();
    g.f[k].g1 = v[k].imag() / omega;
  }
  return g;
}

}  // namespace

ExpPhi exp_phi(const Matrix2& m) noexcept {
  const double c = 0.5 * (m(0, 0) + m(1, 1));
  const double a = 0.5 * (m(0, 0) - m(1, 1));
  // δ² = c² − det(M) = ((m00 − m11)/2)² + m01·m10, free of the cancellation in c² − det.
  const double delta2 = a * a + m(0, 1) * m(1, 0);
  const G g = coefficients(c, delta2, m(0, 0) * m(1, 1) - m(0, 1) * m(1, 0));
  // f(M) = g0·I + g1·N, N = M − cI = [[a, m01], [m10, −a]], entry by entry (a copy of M
  // shifted in place and then read as a vector is a store the load cannot be forwarded from).
  ExpPhi out;
  Matrix2* f[3] = {&out.exp, &out.phi1, &out.phi2};
  for (int k = 0; k < 3; ++k) {
    *f[k] << g.f[k].g0 + g.f[k].g1 * a, g.f[k].g1 * m(0, 1), g.f[k].g1 * m(1, 0),
        g.f[k].g0 - g.f[k].g1 * a;
  }
  return out;
}

Phi12 phi12(double z) noexcept {
  if (std::abs(z) <= kShortSeriesRadius) {
    // Eight terms in Estrin's order: three levels of products instead of a chain of eight (the
    // slow pole of a stiff pair, whose φ waits on nothing else).
    const double p2 = phi2_series<8>(RealAlgebra{}, z);
    return {1.0 + z * p2, p2};
  }
  if (std::abs(z) < 0.5) {
    // φ2 from its series Σ z^j/(j+2)! until the next term cannot change the sum (4 terms at
    // |z| = 1e-3, 16 at 0.5), then φ1 = 1 + z·φ2.
    double p2 = 0.0, term = 0.5;
    for (std::size_t j = 0; j < 16; ++j) {
      p2 += term;
      term *= z * kInverse[j + 3];
      if (converged(term, p2)) break;
    }
    return {1.0 + z * p2, p2};
  }
  const double p1 = std::expm1(z) / z;
  return {p1, (p1 - 1.0) / z};
}

std::array<double, 6> phi_functions(double z) noexcept {
  return phis(z);
}

}  // namespace scp::refine

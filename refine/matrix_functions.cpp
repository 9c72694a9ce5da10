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

// φ1 and φ2 at complex z.
std::array<Complex, 2> phi12_of(Complex z) noexcept {
  if (std::abs(z) < kSeriesRadius) {
    Complex p1 = 0.0, p2 = 0.0, t1 = 1.0, t2 = 0.5;  // z^j/(j+1)!, z^j/(j+2)!
    for (int j = 0; j < kSeriesTerms; ++j) {
      p1 += t1;
      p2 += t2;
      t1 *= z / static_cast<double>(j + 2);
      t2 *= z / static_cast<double>(j + 3);
    }
    return {p1, p2};
  }
  const Complex p1 = (std::exp(z) - 1.0) / z;
  return {p1, (p1 - 1.0) / z};
}

// e^z, φ1(z), φ2(z) at real z (e^z = 1 + z·φ1: one transcendental call, not two).
std::array<double, 3> phis_of_real(double z) noexcept {
  const Phi12 p = phi12(z);
  return {std::abs(z) < 0.5 ? 1.0 + z * p.phi1 : std::exp(z), p.phi1, p.phi2};
}

// φ0..φ5 at real z (for the derivatives in the repeated-eigenvalue branch).
std::array<double, 6> phis(double z) noexcept {
  std::array<double, 6> p{};
  if (std::abs(z) < kSeriesRadius) {
    for (int k = 0; k < 6; ++k) {
      double term = 1.0;  // z^0/k!
      for (int i = 2; i <= k; ++i) term /= i;
      double sum = 0.0;
      for (int j = 0; j < kSeriesTerms; ++j) {
        sum += term;
        term *= z / static_cast<double>(j + k + 1);
      }
      p[k] = sum;
    }
    return p;
  }
  // Upward recurrence φ_{k+1} = (φ_k − 1/k!)/z: stable for |z| ≥ 1 (errors shrink by 1/|z|).
  p[0] = std::exp(z);
  double inv_fact = 1.0;  // 1/k!
  for (int k = 0; k < 5; ++k) {
    p[k + 1] = (p[k] - inv_fact) / z;
    inv_fact /= (k + 1);
  }
  return p;
}

// The (g0, g1) pairs of the header for f = exp, φ1, φ2.
struct G {
  double g0[3], g1[3];
};

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
      g.g0[k] = p[k] + 0.5 * d2 * delta2;
      g.g1[k] = d1 + d3 * delta2 / 6.0;
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
    for (int k = 0; k < 3; ++k) {
      g.g0[k] = 0.5 * (fp[k] + fm[k]);
      g.g1[k] = (fp[k] - fm[k]) / (lp - lm);
    }
    return g;
  }
  const double omega = std::sqrt(-delta2);
  const Complex z(c, omega);
  const Complex e = std::exp(z);
  const auto f = phi12_of(z);
  const Complex v[3] = {e, f[0], f[1]};
  for (int k = 0; k < 3; ++k) {
    g.g0[k] = v[k].real();
    g.g1[k] = v[k].imag() / omega;
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
  Matrix2 n = m;
  n(0, 0) -= c;
  n(1, 1) -= c;
  ExpPhi out;
  Matrix2* f[3] = {&out.exp, &out.phi1, &out.phi2};
  for (int k = 0; k < 3; ++k) {
    *f[k] = g.g1[k] * n;
    (*f[k])(0, 0) += g.g0[k];
    (*f[k])(1, 1) += g.g0[k];
  }
  return out;
}

Phi12 phi12(double z) noexcept {
  if (std::abs(z) < 0.5) {
    double p1 = 0.0, p2 = 0.0, term1 = 1.0, term2 = 0.5;  // z^j/(j+1)!, z^j/(j+2)!
    // Stops once the next term cannot change the sum (5 terms at |z| = 1e-3, 16 at 0.5).
    for (int j = 0; j < 16 && term1 != 0.0; ++j) {
      p1 += term1;
      p2 += term2;
      if (std::abs(term1) < 1e-17 * std::abs(p1)) break;
      term1 *= z / (j + 2);
      term2 *= z / (j + 3);
    }
    return {p1, p2};
  }
  const double p1 = std::expm1(z) / z;
  return {p1, (p1 - 1.0) / z};
}

std::array<double, 6> phi_functions(double z) noexcept {
  return phis(z);
}

}  // namespace scp::refine

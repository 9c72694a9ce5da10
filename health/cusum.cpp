#include "health/cusum.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>

namespace scp::health {

namespace {

// 2ρ, ρ = −ζ(1/2)/√(2π) = 0.583: the mean overshoot of a Gaussian random walk over a barrier.
constexpr double kSiegmundCorrection = 1.166;
constexpr int kHermiteNodes = 40;

struct Quadrature {
  std::array<double, kHermiteNodes> node{}, weight{};
};

// Gauss–Hermite nodes and weights for E[f(X)], X ~ N(0, 1) (probabilists' Hermite polynomials),
// by Golub–Welsch: the eigenvalues of the Jacobi matrix with off-diagonal √i.
Quadrature make_quadrature() {
  Eigen::MatrixXd jacobi = Eigen::MatrixXd::Zero(kHermiteNodes, kHermiteNodes);
  for (int i = 1; i < kHermiteNodes; ++i) jacobi(i, i - 1) = jacobi(i - 1, i) = std::sqrt(i);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(jacobi);
  Quadrature q;
  for (int i = 0; i < kHermiteNodes; ++i) {
    q.node[i] = eig.eigenvalues()[i];
    q.weight[i] = eig.eigenvectors()(0, i) * eig.eigenvectors()(0, i);
  }
  return q;
}

const Quadrature& quadrature() {
  static const Quadrature q = make_quadrature();
  return q;
}

double two_sided_rate(double mean, double k, double h) noexcept {
  return 1.0 / siegmund_arl(mean, k, h) + 1.0 / siegmund_arl(-mean, k, h);
}

}  // namespace

double siegmund_arl(double mean, double k, double h) noexcept {
  const double drift = mean - k, b = h + kSiegmundCorrection;
  const double x = 2.0 * drift * b;
  if (std::abs(x) < 1e-6) return b * b;
  return (std::exp(-x) + x - 1.0) / (2.0 * drift * drift);
}

double cusum_false_alarm_rate(double k, double h, double bias_variance) noexcept {
  if (!(bias_variance > 0.0)) return two_sided_rate(0.0, k, h);
  const Quadrature& q = quadrature();
  const double s = std::sqrt(bias_variance);
  double rate = 0.0;
  for (int i = 0; i < kHermiteNodes; ++i) rate += q.weight[i] * two_sided_rate(s * q.node[i], k, h);
  return rate;
}

CusumDesign design_cusum(double shift, double arl0_blocks, double bias_variance,
                         double max_k) noexcept {
  CusumDesign d;
  d.k = std::min(0.5 * std::abs(shift), max_k);
  const double target = 1.0 / arl0_blocks;
  double lo = 0.0, hi = 10.0;
  while (cusum_false_alarm_rate(d.k, hi, bias_variance) > target && hi < 1e6) hi *= 2.0;
  for (int i = 0; i < 100 && hi - lo > 1e-9 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    if (cusum_false_alarm_rate(d.k, mid, bias_variance) > target) {
      lo = mid;
    } else {
      hi = mid;
    }
  }
  d.h = hi;
  return d;
}

double cusum_delay(const CusumDesign& design, double shift) noexcept {
  return siegmund_arl(std::abs(shift), design.k, design.h);
}

bool TwoSidedCusum::update(double z, double t_begin) noexcept {
  ++blocks_;
  if (!std::isfinite(z)) return upper_ > design_.h || lower_ > design_.h;
  if (upper_ == 0.0) upper_onset_ = t_begin;
  if (lower_ == 0.0) lower_onset_ = t_begin;
  upper_ = std::max(0.0, upper_ + z - design_.k);
  lower_ = std::max(0.0, lower_ - z - design_.k);
  return upper_ > design_.h || lower_ > design_.h;
}

void TwoSidedCusum::reset() noexcept {
  upper_ = lower_ = 0.0;
  upper_onset_ = lower_onset_ = 0.0;
}

double TwoSidedCusum::ratio() const noexcept {
  return std::max(upper_, lower_) / design_.h;
}

int TwoSidedCusum::direction() const noexcept {
  if (upper_ > design_.h && upper_ >= lower_) return 1;
  if (lower_ > design_.h) return -1;
  return 0;
}

double TwoSidedCusum::onset() const noexcept {
  return upper_ >= lower_ ? upper_onset_ : lower_onset_;
}

}  // namespace scp::health

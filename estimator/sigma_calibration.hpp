#pragma once
// Calibration of the paper law's σ from the estimate's own fluctuation (docs/numerics.md, "σ under
// noise"). Pure, fixed-size, no allocation: it runs in the loop thread.
//
// Why: σ_i² = mean ε² · P_ii / β assumes the prediction error ε is correlated over 1/β. Under
// sensor noise ε is mostly the noise passed through the state-variable filter, and for the thermal
// row that is a high-pass (a_f = β(T − T_f) carries the noise of T): its spectrum vanishes at low
// frequency, so the error of θ̂ — the noise weighted over the forgetting window 1/λP — is two
// orders of magnitude smaller than that σ (bench/montecarlo.md). A lag-1 correlation of ε cannot
// see this (the high-passed noise looks white, τ ≈ one sample, and σ stays an order of magnitude
// too large: docs/numerics.md, "σ under noise"); what matters is the
// noise's spectrum in the band the forgetting window passes.
//
// The law is forgetting-weighted least squares (Rθ̂ = ∫e^{−λP(t−s)} wᵀa ds), so its error is
// P·z with z the exponentially weighted score, z' = −λP z + wᵀe: the sandwich P·Var(z)·P. For ε
// white with spectral density S that is exactly S·P R₂ P, R₂ = ∫e^{−2λP(t−s)} wᵀw ds (BlockRls
// keeps R₂ beside R); coloured noise changes S, not the shape, as long as its spectrum is smooth
// over the band 1/λP passes. So the caller hands in the profile mean ε²·(P R₂ P)_ii and this class
// measures the scalar c_i = S/mean ε² (a correlation time, s) from θ̂'s own fluctuation: θ̂ varies
// around its mean with correlation time 1/λP, so in blocks of B = kBlockTimeConstants/λP the
// within-block variance of ϑ̂_i (divided by the fraction an Ornstein–Uhlenbeck process of time
// constant 1/λP keeps around a block mean) over the block's mean profile is one estimate of c_i;
// the median of the last kBlocks of them (robust to the start-up transient, corrected for the
// median of a χ² with ~B·λP degrees of freedom) is c_i. The caller publishes c_i·profile_i,
// bounded to [1e-8, 1] times the uncalibrated variance; before kMinBlocks blocks, the uncalibrated.
// The profile matters: calibrating P_ii instead left θ̂6's σ right on average but too large at
// one phase of the paper's 0.1 Hz sine (tests/estimator/test_sigma_calibration.cpp).
//
// What it cannot see: a bias that does not fluctuate (errors-in-variables of θ1..θ4 under noise:
// docs/numerics.md, "σ under noise"). That is the refined fit's bias test (refine/bias_test.cpp); a
// σ that is honest about the fluctuation makes that test sharper.

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>

namespace scp::estimator {

template <int N>
class SigmaCalibration {
 public:
  using Vec = Eigen::Matrix<double, N, 1>;

  static constexpr double kBlockTimeConstants = 16.0;  // B·λP
  static constexpr int kBlocks = 9;                    // ring of block ratios (odd: a median)
  static constexpr int kMinBlocks = 3;

  explicit SigmaCalibration(double forgetting = 1.0) noexcept { configure(forgetting); }

  void configure(double forgetting) noexcept {
    block_s_ = kBlockTimeConstants / forgetting;
    // Within-block variance of an OU process of time constant τ over a block B = uτ, as a fraction
    // of its variance: 1 − (2/u)(1 − (1 − e^{−u})/u). Its ~u degrees of freedom put the median of
    // the block ratios at (1 − 2/(9u))³ of their mean (Wilson–Hilferty).
    const double u = kBlockTimeConstants;
    const double within = 1.0 - (2.0 / u) * (1.0 - (-std::expm1(-u)) / u);
    const double median = std::pow(1.0 - 2.0 / (9.0 * u), 3);
    correction_ = 1.0 / (within * median);
    reset();
  }

  void reset() noexcept {
    clear_block();
    filled_ = 0;
    next_ = 0;
    factor_ = Vec::Ones();
  }

  // One step of length h: the scaled estimate ϑ̂ after the step and the variance profile it is
  // calibrated against (scaled coordinates). A few flops per parameter; a median every block.
  void step(const Vec& vartheta, const Vec& profile, double h) noexcept {
    if (!(h > 0.0) || !vartheta.allFinite() || !profile.allFinite()) return;
    if (block_t_ == 0.0) origin_ = vartheta;  // shifted sums: no cancellation at |ϑ| ≫ σ
    const Vec d = vartheta - origin_;
    block_t_ += h;
    sum_d_ += h * d;
    sum_d2_ += h * d.cwiseAbs2();
    sum_raw_ += h * profile;
    if (block_t_ >= block_s_) close_block();
  }

  // c_i: the variance is c_i·profile_i (the caller bounds it). Valid once ready().
  const Vec& factor() const noexcept { return factor_; }
  bool ready() const noexcept { return filled_ >= kMinBlocks; }

 private:
  void clear_block() noexcept {
    block_t_ = 0.0;
    origin_.setZero();
    sum_d_.setZero();
    sum_d2_.setZero();
    sum_raw_.setZero();
  }

  void close_block() noexcept {
    Vec ratio = Vec::Ones();
    for (int i = 0; i < N; ++i) {
      const double mean = sum_d_(i) / block_t_;
      const double var = std::max(0.0, sum_d2_(i) / block_t_ - mean * mean) * correction_;
      const double raw = sum_raw_(i) / block_t_;
      ratio(i) = raw > 0.0 && std::isfinite(var / raw) ? var / raw : 1.0;
    }
    ring_[static_cast<std::size_t>(next_)] = ratio;
    next_ = (next_ + 1) % kBlocks;
    filled_ = std::min(filled_ + 1, kBlocks);
    clear_block();
    if (filled_ < kMinBlocks) return;
    for (int i = 0; i < N; ++i) {
      std::array<double, kBlocks> v{};
      for (int k = 0; k < filled_; ++k)
        v[static_cast<std::size_t>(k)] = ring_[static_cast<std::size_t>(k)](i);
      const auto mid = v.begin() + filled_ / 2;
      std::nth_element(v.begin(), mid, v.begin() + filled_);
      double m = *mid;
      if (filled_ % 2 == 0) m = 0.5 * (m + *std::max_element(v.begin(), mid));
      factor_(i) = m;
    }
  }

  double block_s_ = 16.0;
  double correction_ = 1.0;
  double block_t_ = 0.0;
  Vec origin_ = Vec::Zero();
  Vec sum_d_ = Vec::Zero();
  Vec sum_d2_ = Vec::Zero();
  Vec sum_raw_ = Vec::Zero();
  std::array<Vec, kBlocks> ring_{};
  int filled_ = 0;
  int next_ = 0;
  Vec factor_ = Vec::Ones();
};

}  // namespace scp::estimator

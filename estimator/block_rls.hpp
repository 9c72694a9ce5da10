#pragma once
// One block of the least-squares law (24)-(25) in information form, N parameters, one regressor
// row. The estimator runs two: mechanical (θ1..θ4) and thermal (θ5, θ6), because row 1 of W
// touches only θ1..θ4 and row 2 only θ5, θ6, so with block-diagonal P(0) the law stays
// block-diagonal (PAPER-NOTES, "Structure").
//
// Why information form: eq. (25), Ṗ = λP·P − P wᵀw P, winds up as e^{λP t} in weakly excited
// directions and turns non-finite (PAPER-NOTES). Its inverse R = P⁻¹ obeys the *linear*
//   Ṙ = −λP·R + wᵀw,
// and eq. (24) equals θ̂' = P wᵀ(1 + w P wᵀ)⁻¹ ε = (R + wᵀw)⁻¹ wᵀ ε (matrix inversion lemma).
//
// Scaled coordinates: θ = D·ϑ, w_s = w·D with D = diag(scale). The law is invariant under this
// change of coordinates; only the prior R(0) = I/p0 and the floor R_min = I/p_max are isotropic
// in ϑ, so choosing D ≈ |θ| makes them mean "relative" uncertainty.
//
// Bounded forgetting: Ṙ = −λP (R − R_min) + w_sᵀw_s keeps R ≥ R_min, i.e. P ≤ p_max, SPD,
// whatever the excitation. Per step of length h, with w held over the step (exact):
//   R ← e^{−λP h}(R − R_min) + R_min + ((1 − e^{−λP h})/λP) w_sᵀw_s.
// The estimate takes an explicit step using R before this step's information:
//   ϑ ← ϑ + h (R + w_sᵀw_s)⁻¹ w_sᵀ ε.
// It is stable for any h ≤ 1 s: the eigenvalues of (R + w_sᵀw_s)⁻¹ w_sᵀw_s lie in [0, 1). The
// O(h) step error changes only the convergence rate, never the fixed point ε = 0.
//
// Known parameters: a parameter marked known (free_i = 0) stays at θ0_i. Its regressor column
// is dropped from the law, so with ε = a − w θ̂ computed by the caller the known term moves to
// the measured side: the block is exactly the least-squares law of the remaining parameters.
// R keeps the known rows and columns decoupled (zero off-diagonal), so they never move ϑ.
//
// No allocation: every Eigen object here is fixed-size.

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>

namespace scp::estimator {

// Weights of one step of length h, shared by both blocks (same λP); computed when h changes.
struct ForgettingStep {
  double h = 0.0;      // s
  double decay = 1.0;  // e^{−λP h}
  double gain = 0.0;   // (1 − e^{−λP h})/λP, the step's weight in the forgetting window
  static ForgettingStep make(double forgetting, double h) noexcept {
    const double one_minus = -std::expm1(-forgetting * h);
    return ForgettingStep{.h = h, .decay = 1.0 - one_minus, .gain = one_minus / forgetting};
  }
};

template <int N>
class BlockRls {
 public:
  using Vec = Eigen::Matrix<double, N, 1>;
  using Row = Eigen::Matrix<double, 1, N>;
  using Mat = Eigen::Matrix<double, N, N>;

  struct Settings {
    double forgetting = 0.8;  // λP, 1/s
    double p0 = 100.0;
    double p_max = 1e12;
    double beta = 3.0;  // filter pole: the correlation time 1/β used by sigma()
    Vec scale = Vec::Ones();
    Vec theta0 = Vec::Zero();
    Vec free = Vec::Ones();  // 1: estimated; 0: known, held at theta0
  };

  BlockRls() { reset(); }
  explicit BlockRls(const Settings& s) : s_(s) { reset(); }

  void reset() noexcept {
    vartheta_ = s_.theta0.cwiseQuotient(s_.scale);
    info_ = Mat::Identity() / s_.p0;
    eps2_mean_ = 0.0;
    eps2_weight_ = 0.0;
    window_ = 0.0;
    refresh_diagnostics();
  }

  // w: filtered regressor row in θ coordinates; eps: prediction error a_f − w θ̂ (eq. (20)),
  // computed by the caller before this update.
  void step(const Row& w, double eps, const ForgettingStep& f) noexcept {
    const Row ws = w.cwiseProduct(s_.scale.transpose()).cwiseProduct(s_.free.transpose());
    const Mat wtw = ws.transpose() * ws;
    const Mat a = info_ + wtw;
    const Vec dv = Eigen::LDLT<Mat>(a).solve(ws.transpose() * eps);
    vartheta_ += f.h * dv;

    const double r_min = 1.0 / s_.p_max;
    info_ = f.decay * (info_ - r_min * Mat::Identity()) + f.gain * wtw;
    info_.diagonal().array() += r_min;
    info_ = 0.5 * (info_ + info_.transpose()).eval();

    // Forgetting-weighted mean of ε² over the same window as the information.
    eps2_weight_ = f.decay * eps2_weight_ + f.gain;
    eps2_mean_ += (f.gain / eps2_weight_) * (eps * eps - eps2_mean_);
    window_ = f.decay * window_ + f.gain;
    refresh_diagnostics();
  }

  // A known parameter is theta0 exactly ((θ0/D)·D may differ from θ0 by an ulp).
  Vec theta() const noexcept {
    Vec t = vartheta_.cwiseProduct(s_.scale);
    for (int i = 0; i < N; ++i) {
      if (s_.free(i) < 0.5) t(i) = s_.theta0(i);
    }
    return t;
  }
  double predict(const Row& w) const noexcept { return w.dot(theta()); }

  // σ_i = sqrt(mean ε² · P_ii / β), θ coordinates. The filter makes ε correlated over about 1/β,
  // so the window holds about β·T independent samples and the least-squares variance
  // mean_ε²·(β ∫wᵀw)⁻¹ becomes mean_ε²·P/β. An approximation: it ignores the prior and treats
  // ε as white at spacing 1/β; it is a scale for "how well known", not a confidence bound.
  const Vec& sigma() const noexcept { return sigma_; }
  // Mean information rate of the weakest direction: λ_min(R − R_min)/window, scaled coordinates.
  double excitation() const noexcept { return excitation_; }
  // Largest eigenvalue of P in scaled coordinates, 1/λ_min(R); always ≤ p_max.
  double p_max_eig() const noexcept { return p_max_eig_; }
  // Forgetting window elapsed since reset, (1 − e^{−λP t})/λP, s.
  double window() const noexcept { return window_; }
  double eps2_mean() const noexcept { return eps2_mean_; }

  // Checkpoint exchange in θ coordinates, so a checkpoint survives a change of scale.
  Mat info_theta() const noexcept {
    const Vec inv = s_.scale.cwiseInverse();
    return inv.asDiagonal() * info_ * inv.asDiagonal();
  }
  // Caller validated: finite, symmetric, SPD. The window is taken as saturated (1/λP).
  void restore(const Vec& theta, const Mat& info_theta, double eps2_mean) noexcept {
    // A known parameter keeps the configured value, not the checkpoint's.
    vartheta_ = (theta.cwiseProduct(s_.free) + s_.theta0.cwiseProduct(Vec::Ones() - s_.free))
                    .cwiseQuotient(s_.scale);
    info_ = s_.scale.asDiagonal() * info_theta * s_.scale.asDiagonal();
    info_ = 0.5 * (info_ + info_.transpose()).eval();
    eps2_mean_ = eps2_mean;
    eps2_weight_ = 1.0 / s_.forgetting;
    window_ = 1.0 / s_.forgetting;
    refresh_diagnostics();
  }

  const Mat& info_scaled() const noexcept { return info_; }

 private:
  // Known rows and columns of R: zero off the diagonal, and on it the largest free diagonal
  // entry, so that λ_min(R) and P_ii describe the free parameters only.
  void decouple_known() noexcept {
    if (s_.free.minCoeff() > 0.5) return;
    double d = 0.0;
    for (int i = 0; i < N; ++i) {
      if (s_.free(i) > 0.5) d = std::max(d, info_(i, i));
    }
    if (!(d > 0.0)) d = 1.0 / s_.p0;  // every parameter known
    for (int i = 0; i < N; ++i) {
      if (s_.free(i) > 0.5) continue;
      info_.row(i).setZero();
      info_.col(i).setZero();
      info_(i, i) = d;
    }
  }

  void refresh_diagnostics() noexcept {
    const double r_min = 1.0 / s_.p_max;
    decouple_known();
    Eigen::SelfAdjointEigenSolver<Mat> es;
    es.compute(info_, Eigen::EigenvaluesOnly);
    double l_min = es.eigenvalues()(0);
    if (l_min < r_min) {
      // Mathematically R ≥ R_min, but rounding of order eps·‖R‖ per step accumulates over the
      // window in the weakly excited directions and can push λ_min below R_min (measured: P up to
      // 4e12 for p_max = 1e12 with the voltage held). Lift those eigenvalues back; rare.
      es.compute(info_, Eigen::ComputeEigenvectors);
      const Vec lifted = es.eigenvalues().cwiseMax(r_min);
      info_ = es.eigenvectors() * lifted.asDiagonal() * es.eigenvectors().transpose();
      info_ = 0.5 * (info_ + info_.transpose()).eval();
      l_min = lifted.minCoeff();
      decouple_known();  // the rebuilt R carries rounding-level coupling into known rows
    }
    // P = R⁻¹ only for its diagonal; fixed-size, no allocation.
    const Mat p = Eigen::LDLT<Mat>(info_).solve(Mat::Identity());
    sigma_ = (eps2_mean_ * p.diagonal().array().abs() / s_.beta)
                 .sqrt()
                 .matrix()
                 .cwiseProduct(s_.scale)
                 .cwiseProduct(s_.free);
    p_max_eig_ = 1.0 / l_min;
    excitation_ = window_ > 0.0 ? std::max(0.0, (l_min - r_min) / window_) : 0.0;
  }

  Settings s_{};
  Vec vartheta_ = Vec::Zero();
  Mat info_ = Mat::Identity();
  double eps2_mean_ = 0.0;
  double eps2_weight_ = 0.0;
  double window_ = 0.0;
  Vec sigma_ = Vec::Zero();
  double excitation_ = 0.0;
  double p_max_eig_ = 0.0;
};

}  // namespace scp::estimator

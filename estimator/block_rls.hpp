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
#include <limits>

#include "estimator/sigma_calibration.hpp"
#include "estimator/small_ldlt.hpp"

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
    Vec free = Vec::Ones();       // 1: estimated; 0: known, held at theta0
    bool calibrate_sigma = true;  // σ from the estimate's own fluctuation (sigma_calibration.hpp)
  };

  BlockRls() { reset(); }
  explicit BlockRls(const Settings& s) : s_(s), calibration_(s.forgetting) { reset(); }

  void reset() noexcept {
    vartheta_ = s_.theta0.cwiseQuotient(s_.scale);
    info_ = Mat::Identity() / s_.p0;
    info2_ = Mat::Zero();
    eps2_mean_ = 0.0;
    eps2_weight_ = 0.0;
    window_ = 0.0;
    calibration_.reset();
    refresh_diagnostics(true);
  }

  // w: filtered regressor row in θ coordinates; eps: prediction error a_f − w θ̂ (eq. (20)),
  // computed by the caller before this update.
  void step(const Row& w, double eps, const ForgettingStep& f) noexcept {
    const Row ws = w.cwiseProduct(s_.scale.transpose()).cwiseProduct(s_.free.transpose());
    const Mat wtw = ws.transpose() * ws;
    const Mat a = info_ + wtw;
    // Eigen's pivoted LDLᵀ, written out for fixed N with the same bits (small_ldlt.hpp): a
    // different factorization (Cholesky) moves the mechanical θ̂ (R is ill-conditioned), so the
    // solve must repeat Eigen's roundings exactly.
    const Vec dv = small_ldlt_solve<N>(a, ws.transpose() * eps);
    vartheta_ += f.h * dv;

    const double r_min = 1.0 / s_.p_max;
    // Stays exactly symmetric without re-symmetrizing: R is symmetric on entry (reset, restore
    // and the lift make it so) and every entry (i, j) gets the same operations as (j, i).
    info_ = f.decay * (info_ - r_min * Mat::Identity()) + f.gain * wtw;
    info_.diagonal().array() += r_min;
    // R₂ = ∫e^{−2λP(t−s)} w_sᵀw_s ds, the information with squared weights: the sandwich's meat.
    // (1 − e^{−2λP h})/(2λP) = gain·(1 + decay)/2.
    info2_ = (f.decay * f.decay) * info2_ + (0.5 * f.gain * (1.0 + f.decay)) * wtw;

    // Forgetting-weighted mean of ε² over the same window as the information.
    eps2_weight_ = f.decay * eps2_weight_ + f.gain;
    eps2_mean_ += (f.gain / eps2_weight_) * (eps * eps - eps2_mean_);
    window_ = f.decay * window_ + f.gain;
    refresh_diagnostics();
    if (s_.calibrate_sigma) {
      calibration_.step(vartheta_, profile_, f.h);
      apply_calibration();
    }
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

  // σ_i = sqrt(c_i · mean ε² · P_ii / β), θ coordinates. The filter makes ε correlated over about
  // 1/β, so the window holds about β·T independent samples and the least-squares variance
  // mean_ε²·(β ∫wᵀw)⁻¹ becomes mean_ε²·P/β. That treats ε as white at spacing 1/β; under sensor
  // noise it is far too large for the thermal pair (docs/numerics.md, "σ under noise").
  // Calibrated (sigma_calibration.hpp): the
  // sandwich's shape mean ε²·(P R₂ P)_ii scaled by c_i measured from θ̂_i's own fluctuation, within
  // [1e-8, 1] of that formula; the formula itself until three blocks of 16/λP have passed, and
  // always with calibrate_sigma off.
  const Vec& sigma() const noexcept { return sigma_; }
  // Persistent excitation, scale-free, in [0, 1]: λ_min(D^-½ (R − R_0) D^-½), D = diag(R), where
  // R_0 is what R holds without data (the floor R_min and what is left of the prior I/p0). It is
  // the smallest eigenvalue of the data's information in correlation form, so a column's units,
  // `estimator.scale` and the signal's amplitude cancel out: 1 = every direction excited
  // independently, 0 = a direction not excited (or two columns moving together). The diagonal
  // D includes R_0 so that information faded to the floor reads 0, not its old shape.
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
    info2_ = 0.5 * info_;  // a saturated window's R₂ for a steady regressor
    eps2_mean_ = eps2_mean;
    eps2_weight_ = 1.0 / s_.forgetting;
    window_ = 1.0 / s_.forgetting;
    calibration_.reset();  // the fluctuation is measured again from here
    refresh_diagnostics(true);
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

  // σ every step; λ_min(R) (p_max_eig, excitation, and the lift of eigenvalues below R_min) from
  // an eigen-decomposition only when needed: the 4×4 eigenvalue solve alone costs most of an
  // update (bench_estimator; docs/numerics.md, "Figures behind the code comments"). P = R⁻¹ comes
  // first (σ needs its diagonal), and λ_min(R) = 1/λ_max(P) ≥ 1/trace(P) gives a bound for free:
  // - 1/trace(P) ≥ 2·(R_min + 1e3·eps·N·‖R‖): the eigen-decomposition would have found
  //   λ_min ≥ R_min too (both computations are backward stable to a few eps·‖R‖), so there is
  //   nothing to lift and it is skipped: the same R, θ̂ and σ as deciding with it.
  // - 1/trace(P) < R_min: possibly below the floor; the eigen-decomposition runs and lifts as
  //   it always did (weakly excited directions with P near p_max: every step, as before).
  // - In between, λ_min of the computed R (up to its own rounding) is ≥ R_min but not by a margin
  //   double precision resolves. This is the regime of an R_min below eps·‖R‖ (the paper's
  //   unscaled p_max = 1e20, ‖R‖ ≈ 3e3): there the eigen-decomposition's λ_min is rounding noise
  //   of ±eps·‖R‖, and lifting on it every step only injected that noise. It runs every
  //   kEigenInterval steps instead, which bounds the drift it corrects (eps·‖R‖ per step) to 16
  //   steps' worth.
  // p_max_eig and excitation of the 4-parameter block are refreshed with the eigen-decomposition,
  // so they may be up to kEigenInterval − 1 steps (16 ms at 1 kHz) old; they describe the
  // excitation over the forgetting window (1/λP ≈ 1 s) and are polled at ≤ 100 Hz. N = 2 uses the
  // closed form every step. Reset and restore refresh everything at once.
  static constexpr int kEigenInterval = 16;
  // excitation() of N > 2 is a diagnostic only (θ̂ never depends on it) describing a window of
  // 1/λP ≈ 1 s: its own eigenvalue solve runs every kExcitationInterval steps (64 ms at 1 kHz),
  // not every kEigenInterval, where it cost a noticeable share of an update (callgrind;
  // docs/numerics.md, "Figures behind the code comments").
  static constexpr int kExcitationInterval = 64;
  // The sandwich profile (P R₂ P)_ii (σ's shape and the calibration's reference) is refreshed
  // every kProfileInterval steps and held in between: it changes with the forgetting window
  // (~1 s), so holding it 3 ms moves σ by far less than σ's own uncertainty. It never feeds θ̂.
  static constexpr int kProfileInterval = 4;
  static_assert(kExcitationInterval % kEigenInterval == 0);

  // sqrt(x² + y²) for the closed forms of N = 2: std::hypot's overflow guard costs more than the
  // arithmetic, every step (callgrind; docs/numerics.md, "Figures behind the code comments"). The
  // squares of an information matrix's entries stay far inside double's range; hypot is kept for a
  // result that is not finite or is zero.
  static double root_of_squares(double x, double y) noexcept {
    const double r = std::sqrt(x * x + y * y);
    return std::isfinite(r) && r > 0.0 ? r : std::hypot(x, y);
  }

  // excitation() of N > 2 needs an eigenvalue solve of its own: every kExcitationInterval steps,
  // at steps ≡ kEigenInterval/2 (mod kEigenInterval), so that it never falls in the same step as
  // λ_min(R)'s (kExcitationInterval is a multiple of kEigenInterval). N = 2 has a closed form and
  // refreshes it every step.
  double scale_free_excitation() const noexcept {
    const double r_min = 1.0 / s_.p_max;
    // e^{−λP t} = 1 − λP·window: the weight left on the prior R(0) = I/p0 (0 after a restore).
    const double prior = std::clamp(1.0 - s_.forgetting * window_, 0.0, 1.0);
    const double r0 = r_min + prior * (1.0 / s_.p0 - r_min);
    Vec inv_sqrt;
    for (int i = 0; i < N; ++i) {
      const double d = info_(i, i);
      if (!(d > 0.0) || !std::isfinite(d)) return 0.0;
      inv_sqrt(i) = 1.0 / std::sqrt(d);
    }
    Mat c = info_;
    c.diagonal().array() -= r0;
    c = (inv_sqrt.asDiagonal() * c * inv_sqrt.asDiagonal()).eval();
    double l_min = 0.0;
    if constexpr (N == 2) {
      const double a = c(0, 0), b = c(0, 1), d = c(1, 1);
      const double l_max = 0.5 * (a + d + root_of_squares(a - d, 2.0 * b));
      l_min = l_max > 0.0 ? (a * d - b * b) / l_max : 0.0;
    } else {
      Eigen::SelfAdjointEigenSolver<Mat> es;
      es.compute(c, Eigen::EigenvaluesOnly);
      l_min = es.eigenvalues()(0);
    }
    return std::isfinite(l_min) ? std::clamp(l_min, 0.0, 1.0) : 0.0;
  }

  // r⁻¹ for symmetric positive definite r through a Cholesky factor and its inverse, written out
  // for fixed N: Eigen's LDLᵀ solve against I went through its generic (dynamic-size, packing)
  // triangular solver, a large share of an update (perf; docs/numerics.md, "Figures behind the code
  // comments"). With r = L·Lᵀ, r⁻¹ = L⁻ᵀL⁻¹. False, `out` untouched, when r is not numerically
  // positive definite.
  static bool inverse(const Mat& r, Mat& out) noexcept {
    double l[N][N] = {};
    for (int j = 0; j < N; ++j) {
      double d = r(j, j);
      for (int k = 0; k < j; ++k) d -= l[j][k] * l[j][k];
      if (!(d > 0.0)) return false;
      l[j][j] = std::sqrt(d);
      for (int i = j + 1; i < N; ++i) {
        double v = r(i, j);
        for (int k = 0; k < j; ++k) v -= l[i][k] * l[j][k];
        l[i][j] = v / l[j][j];
      }
    }
    double m[N][N] = {};  // L⁻¹, lower triangular
    for (int j = 0; j < N; ++j) {
      m[j][j] = 1.0 / l[j][j];
      for (int i = j + 1; i < N; ++i) {
        double v = 0.0;
        for (int k = j; k < i; ++k) v += l[i][k] * m[k][j];
        m[i][j] = -v / l[i][i];
      }
    }
    for (int a = 0; a < N; ++a) {
      for (int b = a; b < N; ++b) {
        double sum = 0.0;
        for (int i = b; i < N; ++i) sum += m[i][a] * m[i][b];
        out(a, b) = sum;
        out(b, a) = sum;
      }
    }
    return true;
  }

  void refresh_diagnostics(bool force_eigen = false) noexcept {
    const double r_min = 1.0 / s_.p_max;
    decouple_known();
    // diag(P), P = R⁻¹: with R = L·Lᵀ, P_ii is the squared norm of column i of L⁻¹. If R is not
    // numerically positive definite the Cholesky fails and the eigen-decomposition below lifts it.
    Mat p = Mat::Constant(std::numeric_limits<double>::quiet_NaN());
    inverse(info_, p);
    Vec p_diag = p.diagonal();
    const double margin =
        1e3 * std::numeric_limits<double>::epsilon() * N * info_.cwiseAbs().maxCoeff();
    const double trace = p_diag.sum();
    const bool bound_usable = std::isfinite(trace) && trace > 0.0;
    const bool surely_above_floor = bound_usable && 1.0 / trace >= 2.0 * (r_min + margin);
    const bool maybe_below_floor = !bound_usable || 1.0 / trace < r_min;
    ++since_eigen_;
    const bool eigen_due = force_eigen || since_eigen_ >= kEigenInterval;
    if (!surely_above_floor && (maybe_below_floor || eigen_due)) {
      Eigen::SelfAdjointEigenSolver<Mat> es;
      es.compute(info_, Eigen::EigenvaluesOnly);
      double l_min = es.eigenvalues()(0);
      if (l_min < r_min) {
        // Mathematically R ≥ R_min, but rounding of order eps·‖R‖ per step accumulates over the
        // window in the weakly excited directions and can push λ_min below R_min (P beyond p_max
        // with the voltage held: docs/numerics.md, "Figures behind the code comments"). Lift those
        // eigenvalues back; rare.
        es.compute(info_, Eigen::ComputeEigenvectors);
        const Vec lifted = es.eigenvalues().cwiseMax(r_min);
        info_ = es.eigenvectors() * lifted.asDiagonal() * es.eigenvectors().transpose();
        info_ = 0.5 * (info_ + info_.transpose()).eval();
        l_min = lifted.minCoeff();
        decouple_known();  // the rebuilt R carries rounding-level coupling into known rows
      }
      if (l_min < r_min || !bound_usable) {
        p = Eigen::LDLT<Mat>(info_).solve(Mat::Identity());
        p_diag = p.diagonal();
      }
      l_min_ = l_min;
      since_eigen_ = 0;
    } else if constexpr (N == 2) {
      // Closed form; l_min = det/l_max avoids the cancellation of (tr − root)/2.
      const double a = info_(0, 0), b = info_(0, 1), d = info_(1, 1);
      const double l_max = 0.5 * (a + d + root_of_squares(a - d, 2.0 * b));
      l_min_ = (a * d - b * b) / l_max;
      if (surely_above_floor) since_eigen_ = 0;
    } else if (eigen_due) {
      Eigen::SelfAdjointEigenSolver<Mat> es;
      es.compute(info_, Eigen::EigenvaluesOnly);
      l_min_ = es.eigenvalues()(0);
      since_eigen_ = 0;
    }
    raw_variance_ = eps2_mean_ * p_diag.array().abs().matrix() / s_.beta;
    // The sandwich's shape: for white ε of spectral density S, Var θ̂ = S·P R₂ P exactly.
    if (force_eigen || ++since_profile_ >= kProfileInterval) {
      const Mat r2p = info2_ * p;
      for (int i = 0; i < N; ++i) profile_(i) = eps2_mean_ * std::abs(p.col(i).dot(r2p.col(i)));
      since_profile_ = 0;
    }
    // With the calibration on, step() applies it after the calibration's own step.
    if (force_eigen || !s_.calibrate_sigma) apply_calibration();
    if (since_eigen_ == 0 || N == 2) p_max_eig_ = 1.0 / l_min_;
    ++since_excitation_;
    if (N == 2 || force_eigen || since_excitation_ >= kExcitationInterval) {
      excitation_ = scale_free_excitation();
      since_excitation_ = force_eigen ? kEigenInterval / 2 : 0;
    }
  }

  // σ² = c_i·profile_i once calibrated, within [1e-8, 1]·raw: never above the uncalibrated σ.
  void apply_calibration() noexcept {
    Vec var = raw_variance_;
    if (s_.calibrate_sigma && calibration_.ready()) {
      for (int i = 0; i < N; ++i) {
        const double c = calibration_.factor()(i) * profile_(i);
        if (std::isfinite(c)) var(i) = std::clamp(c, kVarianceFloor * var(i), var(i));
      }
    }
    sigma_ = var.cwiseSqrt().cwiseProduct(s_.scale).cwiseProduct(s_.free);
  }
  static constexpr double kVarianceFloor = 1e-8;  // σ at least 1e-4 of the uncalibrated one

  Settings s_{};
  SigmaCalibration<N> calibration_{s_.forgetting};
  Vec raw_variance_ = Vec::Zero();  // mean ε²·P_ii/β, scaled coordinates
  Vec profile_ = Vec::Zero();       // mean ε²·(P R₂ P)_ii, scaled coordinates
  Mat info2_ = Mat::Zero();         // R₂, scaled coordinates
  Vec vartheta_ = Vec::Zero();
  Mat info_ = Mat::Identity();
  double eps2_mean_ = 0.0;
  double eps2_weight_ = 0.0;
  double window_ = 0.0;
  Vec sigma_ = Vec::Zero();
  double excitation_ = 0.0;
  double p_max_eig_ = 0.0;
  double l_min_ = 0.0;   // λ_min(R) at the last eigen-decomposition (or closed form)
  int since_eigen_ = 0;  // steps since then
  // Steps since excitation_ was computed; starts half an interval out of step with since_eigen_.
  int since_excitation_ = kEigenInterval / 2;
  int since_profile_ = 0;  // steps since profile_ was computed
};

}  // namespace scp::estimator

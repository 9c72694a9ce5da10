#pragma once
// Online least-squares identification of the SCP actuator (paper, Section III): filters
// (9)-(15), prediction error (20), update law (24)-(25) in information form, run as two
// independent blocks (mechanical θ1..θ4, thermal θ5, θ6). A pure library: no I/O, no logging,
// no clock (time comes with each Measurement), no allocation in update().
//
// Numerics (error orders):
// - Filters β/(s+β) are discretized exactly for inputs linear between samples (first-order hold,
//   hold_filter.hpp), plus a quadratic correction through the previous sample once it exists:
//   exact for quadratics, O(h³) global error for smooth inputs. Plain FOH (O(h²)) leaves a bias
//   in the mechanical θ̂ at 1 kHz because the stiffness k/m multiplies its error
//   (docs/numerics.md, "Filters"). With
//   VoltageHold::zoh the V² column instead uses the exact zero-order-hold update, because a DAC
//   holds the voltage of sample k+1 over (t_k, t_{k+1}]; that column is then exact. When the
//   voltage changed inside the interval (Measurement::voltage_since), the step is split there:
//   still exact. T̄'s columns then follow the exact path of a lag driven by that held V², with
//   θ̂5 (held_lag.hpp), kink at the switch included. Sample intervals need not be uniform: the
//   coefficients follow each step's h.
// - On the first sample (and after a filter restart) W_f = 0 and p = −βv, so a_f = 0 (eq. (9)
//   with a_f(0) = 0); a_f = W_f θ then holds for the continuous system even if the actuator was
//   moving when we started. That sample only initializes.
// - The update law is block_rls.hpp: exact discretization of the (bounded-forgetting)
//   information equation, explicit O(h) step for θ̂ whose error changes only the convergence
//   rate, never the fixed point ε = 0.
// - ε = a_f − W_f θ̂ uses θ̂ before this sample's update.

#include <array>
#include <cstdint>
#include <limits>

#include "estimator/block_rls.hpp"
#include "estimator/hold_filter.hpp"
#include "estimator/types.hpp"

namespace scp::estimator {

// One sample: s, m, m/s, °C above ambient, V. `voltage` is the voltage applied from
// `voltage_since` until t; before `voltage_since` (within the interval since the previous sample)
// the previous sample's voltage was applied. The default, −∞ (or any instant at or before the
// previous sample), is a DAC that switches at sample instants: `voltage` over the whole interval.
// A link whose write lands mid-cycle gives the instant it landed (drivers/sample.hpp).
struct Measurement {
  double t;
  double x;
  double xdot;
  double tbar;
  double voltage;
  double voltage_since = -std::numeric_limits<double>::infinity();
};

enum class VoltageHold { zoh, foh };

// Defaults are what a real daemon should use; the paper's gains are beta = 3, forgetting = 0.8,
// p0 = 100 with scale = 1. Every field is checked by the Estimator constructor.
struct EstimatorConfig {
  double beta = 3.0;        // rad/s, filter pole, eqs. (9)-(15); (0, 1e4]
  double forgetting = 0.8;  // λP, 1/s, eq. (25); (0, 1e3]
  // λP of the mechanical block alone; 0 = `forgetting`. Separating b from α1 needs T̄ to change
  // within the window (columns ẋ and T̄ẋ), which takes the thermal time scale, not 1/0.8 s.
  double forgetting_mechanical = 0.0;
  double p0 = 100.0;    // P(0) = p0·diag(scale)² (paper: 100·I with scale = 1); (0, p_max]
  double p_max = 1e10;  // bound on P in scaled coordinates (information floor 1/p_max)
  Vector6 theta0 = Vector6::Zero();  // initial θ̂, finite
  Vector6 scale = Vector6::Ones();  // parameter scale D: θ = D·ϑ; each > 0. ≈|θ| is sensible.
  // Known parameters are held at theta0 and leave the regression (block_rls.hpp). The data pin
  // down ratios such as b/k far better than the common scale of θ1..θ4 (PAPER-NOTES, "Noise"):
  // one known mechanical parameter, e.g. k/m from a static stiffness test, fixes that scale.
  std::array<bool, 6> known{};
  VoltageHold voltage_hold = VoltageHold::zoh;
  double max_gap_periods = 10;   // a gap larger than this many nominal periods restarts the filters
  double nominal_period = 1e-3;  // s
  // Input validity: a sample outside these is skipped and counted.
  double x_abs_max = 1.0;             // m
  double xdot_abs_max = 10.0;         // m/s
  double tbar_min = -50;              // °C above ambient
  double tbar_max = 200;              // °C above ambient
  double voltage_max = 100;           // V, applies to |V|
  double converged_rel_sigma = 0.01;  // a block is "converged" when every σ_i/|θ̂_i| is below this
};

enum class UpdateOutcome {
  applied,            // filters and estimate advanced
  initialized,        // first sample after reset/restore: filters initialized, no estimate step
  skipped_nonfinite,  // a field was NaN/Inf; nothing changed but the counter
  skipped_range,      // a field was outside the validity ranges; nothing changed but the counter
  skipped_time,       // t did not advance; nothing changed but the counter
  filters_restarted,  // gap too long: filters re-initialized at this sample, θ̂ and R kept
};

const char* to_string(UpdateOutcome outcome) noexcept;

// Everything per update. Index 0 of the Vector2 fields is the mechanical block/row, 1 thermal.
struct Estimate {
  double t = 0.0;  // s, time of the last sample used (applied/initialized/restarted)
  Vector6 theta_hat = Vector6::Zero();
  Vector6 sigma = Vector6::Zero();       // per-parameter standard deviation, see BlockRls::sigma()
  Vector2 eps = Vector2::Zero();         // ε = a_f − W_f θ̂, eq. (20), θ̂ before this update
  Vector2 af = Vector2::Zero();          // eq. (10)
  Vector2 af_hat = Vector2::Zero();      // W_f θ̂, eq. (18), θ̂ before this update
  Vector2 excitation = Vector2::Zero();  // λ_min(R − R_min)/window, scaled coordinates
  bool converged_mech = false;
  bool converged_thermal = false;
  double p_max_eig_mech = 0.0;  // largest eigenvalue of P, scaled coordinates (≤ p_max)
  double p_max_eig_thermal = 0.0;
  std::uint64_t updates = 0;  // outcome applied
  std::uint64_t skipped_nonfinite = 0;
  std::uint64_t skipped_range = 0;
  std::uint64_t skipped_time = 0;
  std::uint64_t filter_restarts = 0;
};

// For checkpoints. Information matrices R = P⁻¹ in θ (unscaled) coordinates so that a checkpoint
// survives a change of `scale`.
struct State {
  Vector6 theta_hat;
  Eigen::Matrix4d info_mech;
  Eigen::Matrix2d info_thermal;
  Vector2 eps2_mean;
  double t;
};

class Estimator {
 public:
  // Throws std::invalid_argument naming the bad field, its value and the allowed range.
  explicit Estimator(const EstimatorConfig& config);

  // Cold start: θ̂ = theta0, P = P(0), filters cleared, counters zeroed.
  void reset() noexcept;
  UpdateOutcome update(const Measurement& m) noexcept;
  const Estimate& estimate() const noexcept { return estimate_; }
  State state() const noexcept;
  // false (and no change) if any entry is non-finite or an information matrix is not symmetric
  // positive definite. Counters are kept; the filters restart on the next sample.
  bool restore(const State& s) noexcept;
  const EstimatorConfig& config() const noexcept { return config_; }
  // W_f of eq. (15) after the last sample (zero right after initialization); for diagnostics and
  // tests of the identity a_f = W_f θ (eq. (17)).
  Regressor filtered_regressor() const noexcept;

 private:
  void start_filters(const Measurement& m) noexcept;
  void refresh_estimate() noexcept;

  EstimatorConfig config_;
  BlockRls<4> mech_;
  BlockRls<2> thermal_;

  // Filter state: filtered columns of W (0..3 row 1, 4..5 row 2, eq. (15)), p (eq. (14)), and
  // the previous sample's inputs for the first-order hold.
  Vector6 wf_ = Vector6::Zero();
  Vector2 p_ = Vector2::Zero();
  Vector6 u_prev_ = Vector6::Zero();
  Vector2 v_prev_ = Vector2::Zero();
  Vector6 u_prev2_ = Vector6::Zero();  // one sample further back, for the quadratic correction
  Vector2 v_prev2_ = Vector2::Zero();
  double h_prev_ = 0.0;  // t_prev − t_prev2; 0 while only one sample is known
  double t_prev_ = 0.0;
  bool filters_running_ = false;

  double h_cached_ = -1.0;
  HoldCoefficients hold_{};
  ForgettingStep forget_mech_{};
  ForgettingStep forget_thermal_{};

  Estimate estimate_{};
};

}  // namespace scp::estimator

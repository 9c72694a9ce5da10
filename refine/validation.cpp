#include "refine/validation.hpp"

#include <algorithm>
#include <cmath>

#include "refine/parameters.hpp"
#include "refine/validation_layout.hpp"

namespace scp::refine {

namespace {

// The damping the stiffness candidate's filter was discretized with is reused until T̄ moves it
// by this fraction: the candidate only has to be the term's sensitivity to first order (its test
// is exact whatever regressor it uses).
constexpr double kDampingTolerance = 1e-3;
// Sample intervals that differ by less than this fraction share one discretization: t_k − t_{k−1}
// of a uniform record differs in its last bits from sample to sample.
constexpr double kIntervalTolerance = 1e-6;

bool same_interval(double a, double b) {
  return std::abs(a - b) <= kIntervalTolerance * b;
}

double block_length(double time_constant, int per_time_constant) {
  const double n = std::max(1, per_time_constant);
  return time_constant > 0.0 && std::isfinite(time_constant) ? time_constant / n : 1.0;
}

}  // namespace

const char* test_name(ValidationTest test) noexcept {
  // In the enum's order: the names the protocol publishes.
  static constexpr const char* kNames[kValidationTests] = {
      "whiteness_x",       "noise_ratio_x",    "independence_x", "displacement_zero",
      "stiffness_tempco",  "thermal_residual", "whiteness_t",    "noise_ratio_t",
      "independence_t",    "ambient_offset",   "ambient_drift",  "sensor_lag",
      "resistance_tempco", "cooling_tempco"};
  const int i = static_cast<int>(test);
  return i >= 0 && i < kValidationTests ? kNames[i] : "none";
}

ValidationBlock block_of(ValidationTest test) noexcept {
  return static_cast<int>(test) < static_cast<int>(ValidationTest::kWhitenessT)
             ? ValidationBlock::kMechanical
             : ValidationBlock::kThermal;
}

bool is_structure_test(ValidationTest test) noexcept {
  switch (test) {
    case ValidationTest::kWhitenessX:
    case ValidationTest::kNoiseRatioX:
    case ValidationTest::kWhitenessT:
    case ValidationTest::kNoiseRatioT:
    case ValidationTest::kNone:
      return false;
    default:
      return true;
  }
}

const char* verdict_name(Verdict verdict) noexcept {
  switch (verdict) {
    case Verdict::kAdequate:
      return "adequate";
    case Verdict::kNoiseColored:
      return "noise_colored";
    case Verdict::kStructure:
      return "structure";
    case Verdict::kUntested:
      return "untested";
  }
  return "untested";
}

ModelTimeConstants model_time_constants(const Vector6& theta, double tbar) noexcept {
  ModelTimeConstants out;
  out.thermal_s = theta[4] > 0.0 ? 1.0 / theta[4] : 0.0;
  // s² + c s + k: the slower root's |Re| is c/2 − √(c²/4 − k) when real, c/2 when complex.
  const double c = theta[0] + theta[1] * tbar, k = theta[2];
  if (!(c > 0.0) || !(k > 0.0)) return out;
  const double disc = 0.25 * c * c - k;
  // c/2 − √(c²/4 − k) = k/(c/2 + √(c²/4 − k)): no cancellation for the paper's c² ≫ 4k.
  const double slow = disc > 0.0 ? k / (0.5 * c + std::sqrt(disc)) : 0.5 * c;
  out.mechanical_s = 1.0 / slow;
  return out;
}

ResidualValidator::ResidualValidator(const Vector6& theta, const ValidationSettings& settings)
    : theta_(theta),
      settings_(settings),
      mechanical_(
          block_length(settings.mechanical_time_constant_s, settings.blocks_per_time_constant),
          layout::mechanical_fields(settings), settings.max_blocks),
      thermal_(block_length(settings.thermal_time_constant_s, settings.blocks_per_time_constant),
               layout::thermal_fields(settings), settings.max_blocks) {
  settings_.jacobian_columns = layout::jacobian_columns(settings);
}

void ResidualValidator::advance_candidates(const ValidationSample& s, double dt) noexcept {
  if (!(dt > 0.0)) return;
  // Thermal candidates: ṡ = −θ5 s + f with f held over the interval at its value at t.
  if (!same_interval(dt, thermal_dt_)) {
    const double z = -theta_[4] * dt;
    thermal_decay_ = std::exp(z);
    thermal_gain_ = dt * phi12(z).phi1;
    thermal_dt_ = dt;
  }
  const double tbar = s.tbar_model;
  s_resistance_ =
      thermal_decay_ * s_resistance_ + thermal_gain_ * (-theta_[5] * s.thermal_input * tbar);
  s_cooling_ = thermal_decay_ * s_cooling_ + thermal_gain_ * (-theta_[4] * tbar * tbar);
  // Stiffness candidate: s̈ = −(θ1 + θ2 T̄) ṡ − θ3 s + θ3 T̄ x, exactly for the frozen damping.
  const double damping = theta_[0] + theta_[1] * s.mechanical_input;
  if (!same_interval(dt, mechanical_dt_) ||
      std::abs(damping - mechanical_damping_) > kDampingTolerance * std::abs(mechanical_damping_)) {
    Matrix2 a;
    a << 0.0, 1.0, -theta_[2], -damping;
    mechanical_step_ = exp_phi(a * dt);
    mechanical_dt_ = dt;
    mechanical_damping_ = damping;
  }
  const Eigen::Vector2d stiffness_forcing(0.0, theta_[2] * s.mechanical_input * s.x_model);
  s_stiffness_ =
      mechanical_step_.exp * s_stiffness_ + dt * (mechanical_step_.phi1 * stiffness_forcing);
  // x's response to the T̄ the thermal block missed, were ε_T that (the force −θ4·δT̄; the
  // damping's share θ2·δT̄·ẋ is second order).
  const Eigen::Vector2d thermal_forcing(0.0, -theta_[3] * (s.tbar - s.tbar_model));
  s_thermal_residual_ =
      mechanical_step_.exp * s_thermal_residual_ + dt * (mechanical_step_.phi1 * thermal_forcing);
}

namespace {

// Sensitivities of N columns (Eigen::Dynamic: as many as ValidationSettings says). The fit's
// passes feed one per slot of p (validation_settings()), a length fixed at compile time: the
// per-sample sums then run unrolled in vector registers.
template <int N>
using Columns = Eigen::Matrix<double, N, 1>;
constexpr int kFitColumns = kParams;

template <int N>
Eigen::Map<const Columns<N>> columns_of(std::span<const double> j, Eigen::Index n) {
  return {j.data(), n};
}

// Whether every value is finite, without a branch per value: 0·v is 0 for a finite v and NaN
// for ±∞ or NaN, and a NaN survives the sum.
template <int N>
bool finite_sample(const ValidationSample& s, Eigen::Index x_columns, Eigen::Index tbar_columns) {
  const double values[] = {
      s.t, s.x, s.x_model, s.tbar, s.tbar_model, s.thermal_input, s.mechanical_input};
  double zero = 0.0;
  for (double v : values) zero += 0.0 * v;
  zero += (0.0 * columns_of<N>(s.jacobian_x, x_columns)).sum() +
          (0.0 * columns_of<N>(s.jacobian_tbar, tbar_columns)).sum();
  return zero == 0.0;
}

// Adds a sample's sensitivities to an open block's sums.
template <int N>
void add_columns(double* sums, std::span<const double> j, Eigen::Index columns) {
  Eigen::Map<Columns<N>>(sums, columns) += columns_of<N>(j, columns);
}

}  // namespace

void ResidualValidator::add(const ValidationSample& s) noexcept {
  const auto used = [this](std::span<const double> j) {
    return static_cast<Eigen::Index>(
        std::min(static_cast<std::size_t>(settings_.jacobian_columns), j.size()));
  };
  const Eigen::Index nx = used(s.jacobian_x), nt = used(s.jacobian_tbar);
  const bool fit_columns = nx == kFitColumns && nt == kFitColumns;
  const bool finite = fit_columns ? finite_sample<kFitColumns>(s, nx, nt)
                                  : finite_sample<Eigen::Dynamic>(s, nx, nt);
  if (!finite || (samples_ > 0 && !(s.t > t_prev_))) {
    ++skipped_;
    return;
  }
  const double dt = samples_ > 0 ? s.t - t_prev_ : 0.0;
  advance_candidates(s, dt);
  const double y[2] = {s.x, s.tbar};
  const double model[2] = {s.x_model, s.tbar_model};
  if (samples_ == 0) t_first_ = s.t;
  for (int c = 0; c < 2; ++c) {
    if (samples_ == 0) y_first_[c] = y[c];
    const double e = y[c] - model[c], d = y[c] - y_first_[c];
    rss_[c] += e * e;
    y_sum_[c] += d;
    y_squares_[c] += d * d;
  }
  const double tbar_rate = dt > 0.0 ? (s.tbar_model - tbar_model_prev_) / dt : 0.0;

  double* m = mechanical_.accumulate(s.t);
  m[layout::kTime] += s.t - t_first_;
  m[layout::kResidual] += s.x - s.x_model;
  m[layout::kInput] += s.mechanical_input;
  m[layout::kStiffness] += s_stiffness_[0];
  m[layout::kThermalResidual] += s_thermal_residual_[0];
  if (fit_columns) {
    add_columns<kFitColumns>(m + layout::kMechanicalJacobian, s.jacobian_x, nx);
  } else {
    add_columns<Eigen::Dynamic>(m + layout::kMechanicalJacobian, s.jacobian_x, nx);
  }

  double* th = thermal_.accumulate(s.t);
  th[layout::kTime] += s.t - t_first_;
  th[layout::kResidual] += s.tbar - s.tbar_model;
  th[layout::kInput] += s.thermal_input;
  th[layout::kLag] += -tbar_rate;
  th[layout::kResistance] += s_resistance_;
  th[layout::kCooling] += s_cooling_;
  if (fit_columns) {
    add_columns<kFitColumns>(th + layout::kThermalJacobian, s.jacobian_tbar, nt);
  } else {
    add_columns<Eigen::Dynamic>(th + layout::kThermalJacobian, s.jacobian_tbar, nt);
  }

  ++samples_;
  t_prev_ = s.t;
  tbar_model_prev_ = s.tbar_model;
}

}  // namespace scp::refine

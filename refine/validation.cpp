#include "refine/validation.hpp"

#include <algorithm>
#include <cmath>

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

bool finite_sample(const ValidationSample& s, std::size_t columns) {
  const double values[] = {
      s.t, s.x, s.x_model, s.tbar, s.tbar_model, s.thermal_input, s.mechanical_input};
  for (double v : values)
    if (!std::isfinite(v)) return false;
  for (std::span<const double> j : {s.jacobian_x, s.jacobian_tbar})
    for (std::size_t i = 0; i < std::min(columns, j.size()); ++i)
      if (!std::isfinite(j[i])) return false;
  return true;
}

}  // namespace

void ResidualValidator::add(const ValidationSample& s) noexcept {
  if (!finite_sample(s, static_cast<std::size_t>(settings_.jacobian_columns)) ||
      (samples_ > 0 && !(s.t > t_prev_))) {
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
  const int p = settings_.jacobian_columns;
  const auto jx = s.jacobian_x.first(std::min<std::size_t>(p, s.jacobian_x.size()));
  const auto jt = s.jacobian_tbar.first(std::min<std::size_t>(p, s.jacobian_tbar.size()));

  double* m = mechanical_.accumulate(s.t);
  m[layout::kTime] += s.t - t_first_;
  m[layout::kResidual] += s.x - s.x_model;
  m[layout::kInput] += s.mechanical_input;
  m[layout::kStiffness] += s_stiffness_[0];
  m[layout::kThermalResidual] += s_thermal_residual_[0];
  for (std::size_t j = 0; j < jx.size(); ++j) m[layout::kMechanicalJacobian + j] += jx[j];

  double* th = thermal_.accumulate(s.t);
  th[layout::kTime] += s.t - t_first_;
  th[layout::kResidual] += s.tbar - s.tbar_model;
  th[layout::kInput] += s.thermal_input;
  th[layout::kLag] += -tbar_rate;
  th[layout::kResistance] += s_resistance_;
  th[layout::kCooling] += s_cooling_;
  for (std::size_t j = 0; j < jt.size(); ++j) th[layout::kThermalJacobian + j] += jt[j];

  ++samples_;
  t_prev_ = s.t;
  tbar_model_prev_ = s.tbar_model;
}

}  // namespace scp::refine

#include "drivers/sim/plant.hpp"

#include <algorithm>
#include <cmath>

namespace scp::drivers::sim {

namespace {

double drift_one(double p0, double rate, double t) noexcept {
  return p0 * std::max(kMinDriftFactor, 1.0 + rate * t / 3600.0);
}

}  // namespace

PlantParams drifted(const PlantParams& p0, const PlantDrift& rate, double t) noexcept {
  PlantParams p;
  p.m = drift_one(p0.m, rate.m, t);
  p.R = drift_one(p0.R, rate.R, t);
  p.Cth = drift_one(p0.Cth, rate.Cth, t);
  p.lambda = drift_one(p0.lambda, rate.lambda, t);
  p.b = drift_one(p0.b, rate.b, t);
  p.k = drift_one(p0.k, rate.k, t);
  p.alpha1 = drift_one(p0.alpha1, rate.alpha1, t);
  p.alpha2 = drift_one(p0.alpha2, rate.alpha2, t);
  return p;
}

bool has_drift(const PlantDrift& r) noexcept {
  return r.m != 0 || r.R != 0 || r.Cth != 0 || r.lambda != 0 || r.b != 0 || r.k != 0 ||
         r.alpha1 != 0 || r.alpha2 != 0;
}

std::array<double, 6> theta_of(const PlantParams& p) noexcept {
  return {p.b / p.m,      p.alpha1 / p.m,   p.k / p.m,
          p.alpha2 / p.m, p.lambda / p.Cth, 1.0 / (p.R * p.Cth)};
}

bool changes_dynamics(const PlantDeviations& d) noexcept {
  return d.resistance_tempco != 0 || d.stiffness_softening != 0 || d.cooling_tempco != 0 ||
         d.ambient_drift_c_per_h != 0 || d.temperature_lag_s > 0;
}

namespace {

double tempco_factor(double change) noexcept {
  return std::max(kMinTempcoFactor, 1.0 + change);
}

double shift_at(const PlantDeviations& d, double t) noexcept {
  return d.ambient_offset_c + d.ambient_drift_c_per_h * t / 3600.0;
}

// [x, ẋ, T̄, Ts − configured ambient] and their rates.
struct JointState {
  double x = 0.0, v = 0.0, tbar = 0.0, sensed = 0.0;
};

JointState plus(const JointState& s, double h, const JointState& rate) noexcept {
  return {s.x + h * rate.x, s.v + h * rate.v, s.tbar + h * rate.tbar, s.sensed + h * rate.sensed};
}

// d/dt of the joint state at time t with voltage `volts`: eqs. (1)–(2) with k, R and λ taken at
// the present T̄, the ambient's drift moving T̄'s reference, and the sensor's lag.
JointState rates(const PlantParams& p, const PlantDeviations& d, double t, const JointState& s,
                 double volts) noexcept {
  const double k = p.k * tempco_factor(-d.stiffness_softening * s.tbar);
  const double r = p.R * tempco_factor(d.resistance_tempco * s.tbar);
  const double lambda = p.lambda * tempco_factor(d.cooling_tempco * s.tbar);
  JointState out;
  out.x = s.v;
  out.v = -((p.b + p.alpha1 * s.tbar) * s.v + k * s.x + p.alpha2 * s.tbar) / p.m;
  out.tbar = (volts * volts / r - lambda * s.tbar) / p.Cth - d.ambient_drift_c_per_h / 3600.0;
  if (d.temperature_lag_s > 0) {
    out.sensed = (s.tbar + shift_at(d, t) - s.sensed) / d.temperature_lag_s;
  }
  return out;
}

}  // namespace

Plant::Plant(const PlantParams& params, int substeps_per_ms, const PlantDrift& drift,
             const PlantDeviations& deviations) noexcept
    : p0_(params),
      params_(params),
      drift_(drift),
      deviations_(deviations),
      drifting_(has_drift(drift)),
      joint_(changes_dynamics(deviations)),
      substeps_per_ms_(std::max(1, substeps_per_ms)),
      sensed_(shift_at(deviations, 0.0)) {}

void Plant::set_state(double x, double xdot, double tbar) noexcept {
  x_ = x;
  xdot_ = xdot;
  tbar_ = tbar;
  sensed_ = tbar + ambient_shift();
}

void Plant::set_params(const PlantParams& params) noexcept {
  p0_ = params;
  params_ = drifting_ ? drifted(p0_, drift_, t_) : p0_;
}

double Plant::ambient_shift() const noexcept {
  return shift_at(deviations_, t_);
}

double Plant::sensed_tbar() const noexcept {
  if (deviations_.temperature_lag_s > 0) return sensed_;
  return tbar_ + ambient_shift();
}

double Plant::resistance() const noexcept {
  return params_.R * tempco_factor(deviations_.resistance_tempco * tbar_);
}

void Plant::update_drifted_params(double dt) noexcept {
  // Drift is slow (relative rates per hour): the parameters at the middle of the step are exact
  // to second order in dt.
  if (drifting_) params_ = drifted(p0_, drift_, t_ + 0.5 * dt);
}

long Plant::substeps_for(double dt) const noexcept {
  // The sub-step count grows with dt so that h never leaves RK4's stability region; the cap only
  // keeps the conversion defined for absurd gaps (2^40 sub-steps would take hours anyway).
  const double n_real = std::ceil(dt * 1e3 * substeps_per_ms_ - 1e-9);
  return static_cast<long>(std::clamp(n_real, 1.0, 1099511627776.0));
}

void Plant::step(double voltage, double dt) noexcept {
  if (!(dt > 0.0) || !std::isfinite(dt) || !std::isfinite(voltage)) return;
  if (!joint_) {
    step_paper_model(voltage, dt);
    return;
  }
  const auto held = [voltage](double /*t*/) noexcept { return voltage; };
  step_joint(VoltageOfTime(held), dt);
}

void Plant::step(VoltageOfTime voltage, double dt) noexcept {
  if (!(dt > 0.0) || !std::isfinite(dt)) return;
  step_joint(voltage, dt);
}

void Plant::step_joint(VoltageOfTime voltage, double dt) noexcept {
  update_drifted_params(dt);
  const PlantParams& p = params_;
  const PlantDeviations& d = deviations_;
  const long n = substeps_for(dt);
  const double h = dt / static_cast<double>(n);
  const double t0 = t_;
  JointState s{x_, xdot_, tbar_, sensed_};
  double v_start = voltage(t0);
  for (long i = 0; i < n; ++i) {
    const double ta = t0 + static_cast<double>(i) * h;
    const double tb = i + 1 == n ? t0 + dt : ta + h;
    const double tm = ta + 0.5 * h;
    const double v_mid = voltage(tm), v_end = voltage(tb);
    const JointState k1 = rates(p, d, ta, s, v_start);
    const JointState k2 = rates(p, d, tm, plus(s, 0.5 * h, k1), v_mid);
    const JointState k3 = rates(p, d, tm, plus(s, 0.5 * h, k2), v_mid);
    const JointState k4 = rates(p, d, tb, plus(s, h, k3), v_end);
    s.x += h / 6.0 * (k1.x + 2.0 * k2.x + 2.0 * k3.x + k4.x);
    s.v += h / 6.0 * (k1.v + 2.0 * k2.v + 2.0 * k3.v + k4.v);
    s.tbar += h / 6.0 * (k1.tbar + 2.0 * k2.tbar + 2.0 * k3.tbar + k4.tbar);
    s.sensed += h / 6.0 * (k1.sensed + 2.0 * k2.sensed + 2.0 * k3.sensed + k4.sensed);
    v_start = v_end;
  }
  x_ = s.x;
  xdot_ = s.v;
  tbar_ = s.tbar;
  sensed_ = s.sensed;
  t_ = t0 + dt;
}

void Plant::step_paper_model(double voltage, double dt) noexcept {
  update_drifted_params(dt);
  const PlantParams& p = params_;

  // eq. (2) with V held: T̄(τ) = T̄ss + (T̄0 − T̄ss)·e^{−aτ}, a = λ/Cth, T̄ss = V²/(Rλ).
  const double a = p.lambda / p.Cth;
  const double tbar_ss = voltage * voltage / (p.R * p.lambda);
  const double tbar0 = tbar_;

  // eq. (3): ẍ = −(b + α1 T̄)/m · ẋ − k/m · x − α2/m · T̄.
  const double inv_m = 1.0 / p.m;
  auto accel = [&](double x, double v, double tb) noexcept {
    return -((p.b + p.alpha1 * tb) * v + p.k * x + p.alpha2 * tb) * inv_m;
  };

  const long n = substeps_for(dt);
  const double h = dt / static_cast<double>(n);
  // T̄(τ) − T̄ss, advanced by a constant factor per half sub-step (one exp per step, not 3n).
  const double half_decay = std::exp(-0.5 * a * h);
  double dev = tbar0 - tbar_ss;
  double x = x_, v = xdot_;
  for (long i = 0; i < n; ++i) {
    const double tb0 = tbar_ss + dev;
    dev *= half_decay;
    const double tbh = tbar_ss + dev;
    dev *= half_decay;
    const double tb1 = tbar_ss + dev;
    const double k1x = v, k1v = accel(x, v, tb0);
    const double k2x = v + 0.5 * h * k1v, k2v = accel(x + 0.5 * h * k1x, v + 0.5 * h * k1v, tbh);
    const double k3x = v + 0.5 * h * k2v, k3v = accel(x + 0.5 * h * k2x, v + 0.5 * h * k2v, tbh);
    const double k4x = v + h * k3v, k4v = accel(x + h * k3x, v + h * k3v, tb1);
    x += h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x);
    v += h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
  }
  x_ = x;
  xdot_ = v;
  // The closed form at the step's end, so T̄ carries no accumulated rounding from the factors.
  tbar_ = tbar_ss + (tbar0 - tbar_ss) * std::exp(-a * dt);
  t_ += dt;
}

}  // namespace scp::drivers::sim

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

Plant::Plant(const PlantParams& params, int substeps_per_ms, const PlantDrift& drift) noexcept
    : p0_(params),
      params_(params),
      drift_(drift),
      drifting_(has_drift(drift)),
      substeps_per_ms_(std::max(1, substeps_per_ms)) {}

void Plant::set_state(double x, double xdot, double tbar) noexcept {
  x_ = x;
  xdot_ = xdot;
  tbar_ = tbar;
}

void Plant::set_params(const PlantParams& params) noexcept {
  p0_ = params;
  params_ = drifting_ ? drifted(p0_, drift_, t_) : p0_;
}

void Plant::step(double voltage, double dt) noexcept {
  if (!(dt > 0.0) || !std::isfinite(dt) || !std::isfinite(voltage)) return;
  // Drift is slow (relative rates per hour): the parameters at the middle of the step are exact
  // to second order in dt.
  if (drifting_) params_ = drifted(p0_, drift_, t_ + 0.5 * dt);
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

  // The sub-step count grows with dt so that h never leaves RK4's stability region; the cap only
  // keeps the conversion defined for absurd gaps (2^40 sub-steps would take hours anyway).
  const double n_real = std::ceil(dt * 1e3 * substeps_per_ms_ - 1e-9);
  const long n = static_cast<long>(std::clamp(n_real, 1.0, 1099511627776.0));
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

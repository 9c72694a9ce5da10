#pragma once
// The temperature sensor's first-order lag (NuisanceSettings::sensor_lag): the fit compares the
// measured T̄ with the model's T̄ seen through τs·dy/dt = T̄ − y, applied to the model's output
// sample by sample. Between two samples T̄ is taken linear (it changes on the thermal time
// constant, seconds, against a millisecond's step), for which the step is exact:
//   y1 = e·y0 + (1 − e − c)·T̄0 + c·T̄1,   e = exp(−Δ/τs),   c = 1 − τs(1 − e)/Δ.
// The sensor starts settled on the model's T̄ at the window's first sample (a lag of seconds
// forgets its start within the window's first seconds). A τs ≤ 0 is continued as the lag's
// first-order effect y = T̄ − τs·dT̄/dt (chord slope), smooth through 0, so that a fit of a sensor
// without lag can put τs on either side of 0 without a boundary.

#include <cmath>

#include "refine/parameters.hpp"

namespace scp::refine {

class SensorLag {
 public:
  explicit SensorLag(double tau) noexcept : tau_(tau) {}

  // At the window's first sample: the model's T̄ and (with sensitivities) its ∂T̄/∂p.
  void start(double tbar, const ParamVector* dtbar) noexcept {
    y_ = tbar_ = tbar;
    if (dtbar != nullptr) {
      dy_ = dtbar_ = *dtbar;
      dy_[kSensorLagSlot] = 0.0;
    }
  }

  // Carries on from a reading `y` at the model's T̄ = `tbar` (a simulation restarted from a
  // state; ∂T̄/∂p `dtbar`, or null): the reading's history before the restart is taken to have
  // no sensitivity beyond T̄'s own, as the restarted state's.
  void resume(double y, double tbar, const ParamVector* dtbar) noexcept {
    y_ = y;
    tbar_ = tbar;
    if (dtbar != nullptr) {
      dy_ = dtbar_ = *dtbar;
      dy_[kSensorLagSlot] = 0.0;
    }
  }

  // The reading after `dt` s at the model's T̄ = `tbar` (∂T̄/∂p `dtbar`, or null).
  double advance(double dt, double tbar, const ParamVector* dtbar) noexcept {
    if (!(tau_ > 0.0)) {
      const double slope = (tbar - tbar_) / dt;
      y_ = tbar - tau_ * slope;
      if (dtbar != nullptr) {
        // T̄'s own column for τs (non-zero once the landing filter has corrected T̄ with a
        // lagged innovation), plus the reading's explicit dependence on τs.
        dy_ = *dtbar + (-tau_ / dt) * (*dtbar - dtbar_);
        dy_[kSensorLagSlot] += -slope;
        dtbar_ = *dtbar;
      }
      tbar_ = tbar;
      return y_;
    }
    if (dt != step_.dt) step_ = Step(dt, tau_);  // a uniformly sampled window: once per pass
    const double e = step_.e, one_minus_e = step_.one_minus_e, c = step_.c;
    const double y = e * y_ + (one_minus_e - c) * tbar_ + c * tbar;
    if (dtbar != nullptr) {
      const double de = step_.de, dc = step_.dc;
      // Through e and c; the rest of τs's column follows the other slots' (T̄'s own column for
      // τs is non-zero once the landing filter has corrected T̄ with a lagged innovation).
      const double explicit_dlag = de * y_ + (-de - dc) * tbar_ + dc * tbar;
      dy_ = e * dy_ + (one_minus_e - c) * dtbar_ + c * *dtbar;
      dy_[kSensorLagSlot] += explicit_dlag;
      dtbar_ = *dtbar;
    }
    y_ = y;
    tbar_ = tbar;
    return y_;
  }

  double reading() const noexcept { return y_; }
  // ∂y/∂p: the model's T̄ sensitivities through the lag, and ∂y/∂τs in kSensorLagSlot.
  const ParamVector& sensitivities() const noexcept { return dy_; }

 private:
  // The step's coefficients for one Δ: e, 1 − e, c and their ∂/∂τ (∂e/∂τ = e·r/τ,
  // ∂c/∂τ = e/τ − (1 − e)/Δ, r = Δ/τ).
  struct Step {
    Step() = default;
    Step(double dt_, double tau) noexcept
        : dt(dt_),
          e(std::exp(-dt_ / tau)),
          one_minus_e(-std::expm1(-dt_ / tau)),
          c(1.0 - one_minus_e * tau / dt_),
          de(e * dt_ / (tau * tau)),
          dc(e / tau - one_minus_e / dt_) {}
    double dt = -1.0;  // Δ > 0 always: never a false hit
    double e = 0.0, one_minus_e = 0.0, c = 0.0, de = 0.0, dc = 0.0;
  };

  double tau_;
  Step step_;
  double y_ = 0.0, tbar_ = 0.0;
  ParamVector dy_ = ParamVector::Zero(), dtbar_ = ParamVector::Zero();
};

}  // namespace scp::refine

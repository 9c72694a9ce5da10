#include "refine/validate_fit.hpp"

#include "refine/fitted_sweep.hpp"
#include "refine/model_simulator.hpp"
#include "refine/switch_columns.hpp"
#include "refine/switch_placement.hpp"

namespace scp::refine {

double mean_square_voltage(const WindowSample& prev, const WindowSample& cur,
                           double delay) noexcept {
  Piece pieces[2];
  const int n = pieces_between(prev, cur, pieces, delay);
  double tau = 0.0, sum = 0.0;
  for (int i = 0; i < n; ++i) {
    tau += pieces[i].tau;
    sum += pieces[i].tau * mean_input(pieces[i]);
  }
  return tau > 0.0 ? sum / tau : cur.voltage * cur.voltage;
}

namespace {

double mean_model_tbar(std::span<const WindowSample> window, const AmbientError& ambient) {
  if (window.empty()) return 0.0;
  double sum = 0.0;
  for (const WindowSample& w : window) {
    sum += w.tbar - ambient.offset - ambient.drift_per_s * (w.t - window.front().t);
  }
  return sum / static_cast<double>(window.size());
}

}  // namespace

ValidationSettings validation_settings(std::span<const WindowSample> window, const Vector6& theta,
                                       const std::optional<FreeMask>& free,
                                       const ValidationSettings& base,
                                       const AmbientError& ambient) {
  ValidationSettings v = base;
  if (!(v.mechanical_time_constant_s > 0.0) || !(v.thermal_time_constant_s > 0.0)) {
    const ModelTimeConstants tc = model_time_constants(theta, mean_model_tbar(window, ambient));
    if (!(v.mechanical_time_constant_s > 0.0)) v.mechanical_time_constant_s = tc.mechanical_s;
    if (!(v.thermal_time_constant_s > 0.0)) v.thermal_time_constant_s = tc.thermal_s;
  }
  if (!free) {
    v.jacobian_columns = 0;
    return v;
  }
  v.jacobian_columns = kParams;
  for (int i = 0; i < kParams; ++i) v.fixed_columns[static_cast<std::size_t>(i)] = !(*free)[i];
  const auto disable = [&v](ValidationTest t) { v.disabled[static_cast<std::size_t>(t)] = true; };
  if ((*free)[kXZeroSlot]) disable(ValidationTest::kDisplacementZero);
  if ((*free)[kAmbientOffsetSlot]) disable(ValidationTest::kAmbientOffset);
  if ((*free)[kAmbientDriftSlot]) disable(ValidationTest::kAmbientDrift);
  if ((*free)[kSensorLagSlot]) disable(ValidationTest::kSensorLag);
  if ((*free)[kResistanceTempcoSlot]) disable(ValidationTest::kResistanceTempco);
  if ((*free)[kStiffnessSofteningSlot]) disable(ValidationTest::kStiffnessTempco);
  if ((*free)[kCoolingTempcoSlot]) disable(ValidationTest::kCoolingTempco);
  return v;
}

ValidationReport validate_fit(std::span<const WindowSample> window, const FitResult& fit,
                              ValidationSettings settings, const std::array<bool, 6>& known) {
  settings = validation_settings(
      window, fit.theta, fitted_slots(fit, known), settings,
      AmbientError{fit.nuisance.ambient_offset.value, fit.nuisance.ambient_drift.value});
  ResidualValidator validator(fit.theta, settings);
  sweep_fitted_model(window, fit, [&](const FittedSample& f) {
    const WindowSample& w = window[f.k];
    ValidationSample s;
    s.t = w.t;
    s.x = w.x;
    s.x_model = f.x_model;
    s.tbar = w.tbar;
    s.tbar_model = f.tbar_model;
    s.thermal_input = f.thermal_input;
    s.mechanical_input = f.state->tbar;
    s.jacobian_x = std::span<const double>(f.jx->data(), kParams);
    s.jacobian_tbar = std::span<const double>(f.jt->data(), kParams);
    validator.add(s);
  });
  if (fit.voltage_switches.placed == 0) return validator.finish();
  return validator.finish(placed_switch_columns(window, fit, validator.thermal_layout()));
}

}  // namespace scp::refine

#include "refine/validate_fit.hpp"

#include "refine/model_simulator.hpp"
#include "refine/sensitivities.hpp"
#include "refine/sensor_lag.hpp"

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
  FreeMask free = free_slots(known);
  free[kXZeroSlot] = fit.nuisance.x_zero.estimated;
  free[kAmbientOffsetSlot] = fit.nuisance.ambient_offset.estimated;
  free[kAmbientDriftSlot] = fit.nuisance.ambient_drift.estimated;
  free[kSensorLagSlot] = fit.nuisance.sensor_lag.estimated;
  Tempcos tc;
  double* const coefficient[] = {&tc.rho, &tc.kappa, &tc.gamma};
  bool extended = false;
  for (std::size_t i = 0; i < kExtensionTable.size(); ++i) {
    const ExtensionEstimate& e = fit.extensions.*kExtensionTable[i].estimate;
    free[kExtensionTable[i].slot] = e.kept;
    *coefficient[i] = e.kept ? e.value : 0.0;
    extended = extended || e.kept;
  }
  settings = validation_settings(
      window, fit.theta, free, settings,
      AmbientError{fit.nuisance.ambient_offset.value, fit.nuisance.ambient_drift.value});
  if (window.empty()) return ResidualValidator(fit.theta, settings).finish();
  ResidualValidator validator(fit.theta, settings);
  SensitivitySimulator sim(fit.theta, fit.initial_state, false, tc, extended);
  SensorLag lag(fit.nuisance.sensor_lag.value);
  lag.start(sim.state().tbar, &sim.dtbar());
  for (std::size_t k = 0; k < window.size(); ++k) {
    double u = window[k].voltage * window[k].voltage;
    if (k > 0) {
      sim.advance(window[k - 1], window[k], fit.input_delay_s);
      u = mean_square_voltage(window[k - 1], window[k], fit.input_delay_s);
      lag.advance(window[k].t - window[k - 1].t, sim.state().tbar, &sim.dtbar());
    }
    ParamVector jx = sim.dx(), jt = lag.sensitivities();
    const double since = window[k].t - window.front().t;
    jx[kXZeroSlot] = 1.0;
    jt[kAmbientOffsetSlot] = 1.0;
    jt[kAmbientDriftSlot] = since;
    ValidationSample s;
    s.t = window[k].t;
    s.x = window[k].x;
    s.x_model = sim.state().x + fit.nuisance.x_zero.value;
    s.tbar = window[k].tbar;
    s.tbar_model = lag.reading() + fit.nuisance.ambient_offset.value +
                   fit.nuisance.ambient_drift.value * since;
    s.thermal_input = u;
    s.mechanical_input = sim.state().tbar;
    s.jacobian_x = std::span<const double>(jx.data(), kParams);
    s.jacobian_tbar = std::span<const double>(jt.data(), kParams);
    validator.add(s);
  }
  return validator.finish();
}

}  // namespace scp::refine

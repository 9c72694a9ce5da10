#include "refine/validate_fit.hpp"

#include "refine/model_simulator.hpp"
#include "refine/sensitivities.hpp"

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

ValidationReport validate_fit(std::span<const WindowSample> window, const FitResult& fit,
                              ValidationSettings settings, const std::array<bool, 6>& known) {
  if (window.empty()) return ResidualValidator(fit.theta, settings).finish();
  if (!(settings.mechanical_time_constant_s > 0.0) || !(settings.thermal_time_constant_s > 0.0)) {
    double mean_tbar = 0.0;
    for (const WindowSample& w : window) mean_tbar += w.tbar;
    mean_tbar /= static_cast<double>(window.size());
    const ModelTimeConstants tc = model_time_constants(fit.theta, mean_tbar);
    if (!(settings.mechanical_time_constant_s > 0.0))
      settings.mechanical_time_constant_s = tc.mechanical_s;
    if (!(settings.thermal_time_constant_s > 0.0)) settings.thermal_time_constant_s = tc.thermal_s;
  }
  settings.jacobian_columns = kParams;
  for (int i = 0; i < 6; ++i) settings.fixed_columns[static_cast<std::size_t>(i)] = known[i];
  // The nuisance terms the fit held are not in its span either.
  settings.fixed_columns[kXZeroSlot] = !fit.nuisance.x_zero.estimated;
  settings.fixed_columns[kAmbientOffsetSlot] = !fit.nuisance.ambient_offset.estimated;
  settings.fixed_columns[kAmbientDriftSlot] = !fit.nuisance.ambient_drift.estimated;
  ResidualValidator validator(fit.theta, settings);
  SensitivitySimulator sim(fit.theta, fit.initial_state);
  for (std::size_t k = 0; k < window.size(); ++k) {
    double u = window[k].voltage * window[k].voltage;
    if (k > 0) {
      sim.advance(window[k - 1], window[k], fit.input_delay_s);
      u = mean_square_voltage(window[k - 1], window[k], fit.input_delay_s);
    }
    ParamVector jx = sim.dx(), jt = sim.dtbar();
    const double since = window[k].t - window.front().t;
    jx[kXZeroSlot] = 1.0;
    jt[kAmbientOffsetSlot] = 1.0;
    jt[kAmbientDriftSlot] = since;
    ValidationSample s;
    s.t = window[k].t;
    s.x = window[k].x;
    s.x_model = sim.state().x + fit.nuisance.x_zero.value;
    s.tbar = window[k].tbar;
    s.tbar_model = sim.state().tbar + fit.nuisance.ambient_offset.value +
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

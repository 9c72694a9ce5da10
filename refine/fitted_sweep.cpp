#include "refine/fitted_sweep.hpp"

#include "refine/sensitivities.hpp"
#include "refine/sensor_lag.hpp"
#include "refine/validate_fit.hpp"

namespace scp::refine {

FreeMask fitted_slots(const FitResult& fit, const std::array<bool, 6>& known) {
  FreeMask free = free_slots(known);
  free[kXZeroSlot] = fit.nuisance.x_zero.estimated;
  free[kAmbientOffsetSlot] = fit.nuisance.ambient_offset.estimated;
  free[kAmbientDriftSlot] = fit.nuisance.ambient_drift.estimated;
  free[kSensorLagSlot] = fit.nuisance.sensor_lag.estimated;
  for (const ExtensionSlot& e : kExtensionTable) free[e.slot] = (fit.extensions.*e.estimate).kept;
  return free;
}

Tempcos fitted_tempcos(const FitResult& fit) {
  return tempcos_of(fit.extensions);
}

void sweep_fitted_model(std::span<const WindowSample> window, const FitResult& fit,
                        const std::function<void(const FittedSample&)>& visit) {
  if (window.empty()) return;
  bool extended = false;
  for (const ExtensionSlot& e : kExtensionTable) extended |= (fit.extensions.*e.estimate).kept;
  SensitivitySimulator sim(fit.theta, fit.initial_state, false, fitted_tempcos(fit), extended);
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
    FittedSample s;
    s.k = k;
    s.state = &sim.state();
    s.x_model = sim.state().x + fit.nuisance.x_zero.value;
    s.tbar_model = lag.reading() + fit.nuisance.ambient_offset.value +
                   fit.nuisance.ambient_drift.value * since;
    s.thermal_input = u;
    s.jx = &jx;
    s.jt = &jt;
    visit(s);
  }
}

}  // namespace scp::refine

#include "daemon/analysis/refine/paper_validation.hpp"

#include "refine/model_simulator.hpp"
#include "refine/validate_fit.hpp"

namespace scp::daemon::refine {

using namespace scp::refine;

ValidationReport validate_paper(std::span<const WindowSample> window, const Vector6& theta,
                                const InitialState& initial, double input_delay,
                                const Vector2& declared_noise) {
  ValidationSettings base;
  base.declared_noise = declared_noise;
  // A prediction: no sensitivities to project off (validation_settings with no free slots).
  const ValidationSettings settings = validation_settings(window, theta, std::nullopt, base);
  if (window.empty()) return ResidualValidator(theta, settings).finish();
  ResidualValidator validator(theta, settings);
  ModelState state{initial[0], initial[1], initial[2]};
  ThermalCache cache;
  for (std::size_t k = 0; k < window.size(); ++k) {
    double u = window[k].voltage * window[k].voltage;
    if (k > 0) {
      advance_interval(theta, window[k - 1], window[k], input_delay, state, cache);
      u = mean_square_voltage(window[k - 1], window[k], input_delay);
    }
    ValidationSample s;
    s.t = window[k].t;
    s.x = window[k].x;
    s.x_model = state.x;
    s.tbar = window[k].tbar;
    s.tbar_model = state.tbar;
    s.thermal_input = u;
    s.mechanical_input = state.tbar;
    validator.add(s);
  }
  return validator.finish();
}

}  // namespace scp::daemon::refine

#include "daemon/analysis/refine/paper_validation.hpp"

#include "refine/model_simulator.hpp"
#include "refine/validate_fit.hpp"

namespace scp::daemon::refine {

using namespace scp::refine;

ValidationReport validate_paper(std::span<const WindowSample> window, const Vector6& theta,
                                const InitialState& initial, double input_delay,
                                const Vector2& declared_noise) {
  ValidationSettings settings;
  settings.declared_noise = declared_noise;
  settings.jacobian_columns = 0;
  if (window.empty()) return ResidualValidator(theta, settings).finish();
  double mean_tbar = 0.0;
  for (const WindowSample& w : window) mean_tbar += w.tbar;
  mean_tbar /= static_cast<double>(window.size());
  const ModelTimeConstants tc = model_time_constants(theta, mean_tbar);
  settings.mechanical_time_constant_s = tc.mechanical_s;
  settings.thermal_time_constant_s = tc.thermal_s;
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

#include "refine/switch_perturbation.hpp"

#include <algorithm>

#include "refine/fitted_sweep.hpp"

namespace scp::refine::switch_model {

std::vector<Switch> switch_rows(std::span<const WindowSample> w) {
  std::vector<Switch> out;
  for (std::size_t k = 1; k < w.size(); ++k) {
    const double dt = w[k].t - w[k - 1].t;
    if (w[k].voltage_ramp || !(dt > 0.0)) continue;
    out.push_back(
        {k, std::clamp((w[k].voltage_since - w[k - 1].t) / dt, 0.0, 1.0), Perturbation::Zero()});
  }
  return out;
}

PerturbationSteps::PerturbationSteps(const FitResult& fit, Outputs outputs)
    : theta_(fit.theta),
      tc_(fitted_tempcos(fit)),
      sensor_lag_(fit.nuisance.sensor_lag.value),
      outputs_(outputs),
      mechanical_(fit.theta, tc_) {
  prev_.tbar = fit.initial_state[2];
}

}  // namespace scp::refine::switch_model

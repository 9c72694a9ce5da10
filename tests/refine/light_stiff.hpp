#pragma once
// config/actuators/light-stiff.yaml: the plant and its own excitation (a PRBS with 1 s bits on the
// paper's slow sine, docs/montecarlo.md "Experiment design per actuator"), for the refinement's
// robustness tests and bench_refine's fit time on a stiff actuator.

#include <functional>
#include <memory>

#include "drivers/sim/plant.hpp"
#include "excitation/excitation.hpp"
#include "refine/fit.hpp"

namespace scp::refine::test {

inline drivers::sim::PlantParams light_stiff() {
  drivers::sim::PlantParams p;
  p.m = 0.02;
  p.R = 4.0;
  p.Cth = 0.125;
  p.lambda = 0.025;
  p.b = 2.0;
  p.k = 400.0;
  p.alpha1 = 0.01;
  p.alpha2 = 0.02;
  return p;
}

inline excitation::ExcitationSettings light_stiff_excitation() {
  excitation::ExcitationSettings s;
  s.v_max = 3.2;
  s.offset = 1.16;
  s.sines.push_back({0.6, 0.006, -1.5707963267948966});
  s.prbs.amplitude = 1.2;
  s.prbs.bit_period_s = 1.0;
  return s;
}

inline std::function<double(double)> light_stiff_voltage() {
  auto ex = std::make_shared<excitation::Excitation>(light_stiff_excitation());
  return [ex](double t) { return ex->voltage(t); };
}

// The paper law's estimate when the daemon made its first fit on this actuator (paper voltage, N2,
// seed 1, t = 30 s): the mechanical part collapsed toward 0 with θ3 < 0, as errors-in-variables
// makes it. The hardest start the refinement is handed.
inline Vector6 light_stiff_collapsed_start() {
  Vector6 s;
  s << 3.08, -0.108, -1.51, -7.7e-5, 0.2, 2.0;
  return s;
}

}  // namespace scp::refine::test

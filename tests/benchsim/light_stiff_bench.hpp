#pragma once
// config/actuators/light-stiff.yaml as an scp-benchsim file: its plant and its own excitation (a
// PRBS of 1 s bits on a slow sine), continuous, noise-free; the tests set the rest.

#include <numbers>

#include "tools/benchsim/bench_file.hpp"

namespace scp::tools::benchsim::test {

inline BenchFile light_stiff(double duration_s) {
  BenchFile f = default_bench_file();
  f.sim.plant = {.m = 0.02,
                 .R = 4.0,
                 .Cth = 0.125,
                 .lambda = 0.025,
                 .b = 2.0,
                 .k = 400.0,
                 .alpha1 = 0.01,
                 .alpha2 = 0.02};
  excitation::ExcitationSettings e;
  e.v_max = 3.2;
  e.offset = 1.16;
  e.sines = {{0.6, 0.006, -std::numbers::pi / 2.0}};
  e.prbs.amplitude = 1.2;
  e.prbs.bit_period_s = 1.0;
  f.excitation = e;
  f.duration_s = duration_s;
  return f;
}

}  // namespace scp::tools::benchsim::test

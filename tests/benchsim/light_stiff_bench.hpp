#pragma once
// config/actuators/light-stiff.yaml as an scp-benchsim file: its plant and its own excitation (a
// PRBS of 1 s bits on a slow sine, tests/refine/light_stiff.hpp), continuous, noise-free; the
// tests set the rest.

#include "tests/refine/light_stiff.hpp"
#include "tools/benchsim/bench_file.hpp"

namespace scp::tools::benchsim::test {

inline BenchFile light_stiff(double duration_s) {
  BenchFile f = default_bench_file();
  f.sim.plant = refine::test::light_stiff();
  f.excitation = refine::test::light_stiff_excitation();
  f.duration_s = duration_s;
  return f;
}

}  // namespace scp::tools::benchsim::test

#pragma once
// An scp-benchsim file as the daemon's refinement receives it (read through the replay reader,
// T̄ above the configured ambient), and the plant's θ: for the tests that fit such files.

#include <sstream>
#include <vector>

#include "drivers/replay/csv_trace.hpp"
#include "drivers/sim/plant.hpp"
#include "refine/fit.hpp"
#include "tools/benchsim/bench_file.hpp"

namespace scp::tools::benchsim::test {

// `with_current`: the I column too (WindowSample::current), where the file has one.
inline std::vector<refine::WindowSample> window_of(const BenchFile& f, bool with_current = false) {
  std::ostringstream out;
  write_bench_file(f, out);
  std::istringstream in(out.str());
  const drivers::replay::Trace trace = drivers::replay::parse_trace(in, "bench.csv");
  std::vector<refine::WindowSample> w;
  w.reserve(trace.rows.size());
  for (const drivers::Sample& s : trace.rows) {
    refine::WindowSample r{s.t, s.x, s.temperature - f.sim.ambient_c, s.voltage, s.voltage_since};
    if (with_current) r.current = s.current;
    w.push_back(r);
  }
  return w;
}

inline refine::Vector6 theta_of(const BenchFile& f) {
  const auto th = drivers::sim::theta_of(f.sim.plant);
  refine::Vector6 out;
  for (int i = 0; i < 6; ++i) out[i] = th[static_cast<std::size_t>(i)];
  return out;
}

}  // namespace scp::tools::benchsim::test

// The exponential integrator of refine/model_simulator against the project's RK4 plant.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "refine/model_simulator.hpp"
#include "tests/refine/record.hpp"

namespace scp::refine {
namespace {

struct Deviation {
  double x = 0.0, tbar = 0.0;  // max |model − plant| / max |plant|
};

Deviation deviation(const std::vector<WindowSample>& w, const Vector6& theta) {
  std::vector<ModelState> out(w.size());
  simulate(w, theta, InitialState(w[0].x, 0.0, w[0].tbar), out);
  double dx = 0.0, dt = 0.0, mx = 0.0, mt = 0.0;
  for (std::size_t k = 0; k < w.size(); ++k) {
    dx = std::max(dx, std::abs(out[k].x - w[k].x));
    dt = std::max(dt, std::abs(out[k].tbar - w[k].tbar));
    mx = std::max(mx, std::abs(w[k].x));
    mt = std::max(mt, std::abs(w[k].tbar));
  }
  return {dx / mx, dt / mt};
}

TEST(ModelSimulator, AgreesWithRk4PlantOnThePaperExperiment) {
  const auto w = test::paper_record(300.0);
  const Deviation d = deviation(w, test::theta_of(test::paper_actuator()));
  RecordProperty("x_relative", std::to_string(d.x));
  std::printf("paper experiment 300 s: max relative deviation x %.3g, T %.3g\n", d.x, d.tbar);
  EXPECT_LT(d.x, 1e-11);
  EXPECT_LT(d.tbar, 1e-12);
}

TEST(ModelSimulator, AgreesWithRk4PlantOnAnUnderdampedActuator) {
  const auto w = test::paper_record(60.0, {}, test::underdamped_actuator());
  const Deviation d = deviation(w, test::theta_of(test::underdamped_actuator()));
  std::printf("underdamped 60 s: max relative deviation x %.3g, T %.3g\n", d.x, d.tbar);
  EXPECT_LT(d.x, 1e-11);
  EXPECT_LT(d.tbar, 1e-12);
}

TEST(ModelSimulator, AgreesWithRk4PlantThroughAJitteredLinkWithMidIntervalWrites) {
  const auto w = test::link_record(test::paper_actuator(), 300.0);
  const Deviation d = deviation(w, test::theta_of(test::paper_actuator()));
  std::printf("10 ms ± 2 ms link, voltage landing 3.6 ms late, 300 s: x %.3g, T %.3g\n", d.x,
              d.tbar);
  EXPECT_LT(d.x, 1e-11);
  EXPECT_LT(d.tbar, 1e-12);
}

}  // namespace
}  // namespace scp::refine

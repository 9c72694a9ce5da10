#pragma once
// The estimator driven by the independent RK4 plant (test_plant.hpp) at 1 kHz, for the tests
// that run the paper's experiment.

#include <gtest/gtest.h>

#include <cstdint>
#include <functional>

#include "estimator/estimator.hpp"
#include "tests/estimator/test_plant.hpp"

namespace scp::estimator::test {

inline constexpr double kPeriod = 1e-3;
inline constexpr int kSubsteps = 20;

// Drives plant and estimator from sample k0 to k1 (exclusive). The voltage in sample k is the
// one the DAC held over (t_{k−1}, t_k], i.e. the command computed at t_{k−1}.
struct Rig {
  Estimator est;
  Plant plant;
  std::int64_t k = 0;

  explicit Rig(const EstimatorConfig& c) : est(c) {
    est.update(Measurement{.t = 0.0, .x = 0.0, .xdot = 0.0, .tbar = 0.0, .voltage = 0.0});
  }
  void run_until(double t_end, const std::function<double(double)>& voltage,
                 const std::function<void(const Rig&, double v)>& each = nullptr) {
    while ((k + 1) * kPeriod <= t_end + 1e-9) {
      const double v = voltage(k * kPeriod);
      plant.advance(kPeriod, v, kSubsteps);
      ++k;
      const Measurement m{
          .t = k * kPeriod, .x = plant.x, .xdot = plant.xdot, .tbar = plant.tbar, .voltage = v};
      ASSERT_EQ(est.update(m), UpdateOutcome::applied) << "t=" << m.t;
      if (each) each(*this, v);
    }
  }
};

}  // namespace scp::estimator::test

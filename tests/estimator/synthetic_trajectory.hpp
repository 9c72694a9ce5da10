#pragma once
// A smooth, exciting synthetic trajectory for the estimator's bookkeeping tests (checkpoints,
// counters, masks). Not a plant: its samples obey no model, so no θ is "true" for it.

#include <cmath>

#include "estimator/estimator.hpp"

namespace scp::estimator::test {

inline Measurement sample_at(int k) {
  const double t = k * 1e-3;
  return Measurement{.t = t,
                     .x = 1e-3 * std::sin(0.7 * t),
                     .xdot = 0.7e-3 * std::cos(0.7 * t),
                     .tbar = 20.0 + 10.0 * std::sin(0.3 * t),
                     .voltage = 1.5 + std::sin(2.0 * t)};
}

}  // namespace scp::estimator::test

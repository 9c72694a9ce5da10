#pragma once
// The paper's actuator for the health tests: its four-sine voltage and eqs. (1)-(2) in θ form,
// integrated by RK4 with the voltage held over each loop period (a DAC, as the loop commands
// it). A plant here is never the refined fit's discretization (refine/ integrates the thermal
// state exactly and the mechanical one by an exponential integrator).

#include <array>
#include <cmath>
#include <numbers>

#include "health/types.hpp"

namespace scp::health::test {

inline double paper_voltage(double t) {
  constexpr double w1 = 2.0 * std::numbers::pi * 0.006, w2 = 2.0 * std::numbers::pi * 0.1;
  constexpr double h = std::numbers::pi / 2.0;
  return 1.6 +
         0.4 * (std::sin(w1 * t - h) + std::sin(w1 * t) + std::sin(w2 * t) + std::sin(w2 * t - h));
}

// [x, ẋ, T̄]
using PlantState = std::array<double, 3>;

inline PlantState plant_derivative(const PlantState& s, const Vector6& th, double v) {
  const double x = s[0], xd = s[1], tb = s[2];
  return {xd, -th[0] * xd - th[1] * tb * xd - th[2] * x - th[3] * tb, -th[4] * tb + th[5] * v * v};
}

// One RK4 step of h with the voltage v held.
template <class State, class Derivative>
void rk4_step(State& s, double h, const Derivative& f) {
  const auto add = [](const State& a, const State& d, double k) {
    State r;
    for (std::size_t i = 0; i < a.size(); ++i) r[i] = a[i] + k * d[i];
    return r;
  };
  const State k1 = f(s);
  const State k2 = f(add(s, k1, h / 2));
  const State k3 = f(add(s, k2, h / 2));
  const State k4 = f(add(s, k3, h));
  for (std::size_t i = 0; i < s.size(); ++i)
    s[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
}

}  // namespace scp::health::test

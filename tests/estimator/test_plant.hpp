#pragma once
// An independent reference plant for the estimator tests: the paper's model integrated with RK4
// sub-steps (the project's simulator is someone else's code; these tests must not depend on it).

#include <cmath>
#include <numbers>

namespace scp::estimator::test {

struct PlantParams {  // Table I, written out here on purpose (not from model.cpp)
  double m = 0.1, R = 1.0, Cth = 0.9090, lambda = 0.0540, b = 124.7, k = 181.3, alpha1 = 0.08,
         alpha2 = 0.01;
};

// The paper's excitation, Section IV: 0 ≤ V ≤ 3.2 V.
inline double paper_voltage(double t) {
  const double w1 = 2.0 * std::numbers::pi * 0.006;
  const double w2 = 2.0 * std::numbers::pi * 0.1;
  const double half_pi = std::numbers::pi / 2.0;
  return 1.6 + 0.4 * (std::sin(w1 * t - half_pi) + std::sin(w1 * t) + std::sin(w2 * t) +
                      std::sin(w2 * t - half_pi));
}

class Plant {
 public:
  explicit Plant(PlantParams p = {}) : p_(p) {}
  double x = 0.0, xdot = 0.0, tbar = 0.0;

  // Advance by h with the voltage held at v, using n RK4 sub-steps. The mechanical pole at
  // −1245.5 rad/s needs sub-steps well below 2 ms for RK4 to be stable and accurate.
  void advance(double h, double v, int n) {
    const double dt = h / n;
    for (int i = 0; i < n; ++i) rk4(dt, v);
  }
  // ẍ and dT̄/dt at the current state for voltage v (a = W θ, eq. (8)).
  void accel(double v, double& xdd, double& tdot) const { deriv(x, xdot, tbar, v, xdd, tdot); }

 private:
  void deriv(double x0, double xd, double tb, double v, double& xdd, double& td) const {
    xdd = (-p_.b * xd - p_.alpha1 * tb * xd - p_.k * x0 - p_.alpha2 * tb) / p_.m;
    td = (-p_.lambda * tb + v * v / p_.R) / p_.Cth;
  }
  void rk4(double dt, double v) {
    double a1, t1, a2, t2, a3, t3, a4, t4;
    deriv(x, xdot, tbar, v, a1, t1);
    const double k1x = xdot;
    deriv(x + 0.5 * dt * k1x, xdot + 0.5 * dt * a1, tbar + 0.5 * dt * t1, v, a2, t2);
    const double k2x = xdot + 0.5 * dt * a1;
    deriv(x + 0.5 * dt * k2x, xdot + 0.5 * dt * a2, tbar + 0.5 * dt * t2, v, a3, t3);
    const double k3x = xdot + 0.5 * dt * a2;
    deriv(x + dt * k3x, xdot + dt * a3, tbar + dt * t3, v, a4, t4);
    const double k4x = xdot + dt * a3;
    x += dt / 6.0 * (k1x + 2 * k2x + 2 * k3x + k4x);
    xdot += dt / 6.0 * (a1 + 2 * a2 + 2 * a3 + a4);
    tbar += dt / 6.0 * (t1 + 2 * t2 + 2 * t3 + t4);
  }
  PlantParams p_;
};

}  // namespace scp::estimator::test

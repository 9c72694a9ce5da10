// HeldLagWeights against a closed form written independently: T̄ of a first-order lag driven by
// a piecewise-constant V², and β/(s+β) of it, composed piece by piece from
//   T̄(s) = T∞ + (T0 − T∞)·e^{−as},  y(L) = e^{−βL}·y0 + T∞·(1 − e^{−βL})
//                                          + (T0 − T∞)·β·(e^{−aL} − e^{−βL})/(β − a).
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "estimator/held_lag.hpp"
#include "estimator/hold_filter.hpp"

namespace scp::estimator {
namespace {

constexpr double kBeta = 3.0;

struct LagState {
  double tbar;
  double filtered;
};

// One piece of length L at constant V², for dT̄/dt = −a·T̄ + g·V² (a ≠ β, a > 0).
LagState exact_piece(LagState s, double a, double g, double v2, double length) {
  const double t_inf = g * v2 / a;
  const double y =
      std::exp(-kBeta * length) * s.filtered + t_inf * (1.0 - std::exp(-kBeta * length)) +
      (s.tbar - t_inf) * kBeta * (std::exp(-a * length) - std::exp(-kBeta * length)) / (kBeta - a);
  return {t_inf + (s.tbar - t_inf) * std::exp(-a * length), y};
}

// Random intervals with the voltage switching anywhere inside (or at the start), at 10 ms and
// 1 ms: the weights must reproduce the filtered lag to rounding, from T̄ at the two ends only.
TEST(HeldLag, ExactForALagDrivenByAHeldVoltageSwitchingInsideTheInterval) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const double a = 0.0594, g = 1.1;  // θ5, θ6 of Table I
  for (const double h : {0.01, 0.001}) {
    LagState exact{0.0, 0.0};
    double y = 0.0, v2_prev = 0.0, max_err = 0.0, max_y = 0.0;
    for (int k = 0; k < 20000; ++k) {
      const double v2 = 10.0 * unit(rng);
      const double offset = k % 4 == 0 ? 0.0 : h * unit(rng);  // 0: a DAC at the sample
      const double tbar_prev = exact.tbar;
      exact = exact_piece(exact, a, g, v2_prev, offset);
      exact = exact_piece(exact, a, g, v2, h - offset);
      const HeldLagWeights w =
          HeldLagWeights::make(HoldCoefficients::make(kBeta, h), kBeta, a, v2_prev, v2, offset);
      y = w.step(y, std::exp(-kBeta * h), tbar_prev, exact.tbar);
      max_err = std::max(max_err, std::abs(y - exact.filtered));
      max_y = std::max(max_y, std::abs(exact.filtered));
      v2_prev = v2;
    }
    EXPECT_LT(max_err, 1e-11 * max_y) << "h = " << h;
    // The FOH through the same two samples misses the kink: this test can tell them apart.
    const HoldCoefficients foh = HoldCoefficients::make(kBeta, h);
    LagState e{5.0, 0.0};
    const LagState mid = exact_piece(e, a, g, 0.0, 0.5 * h);
    const LagState end = exact_piece(mid, a, g, 10.0, 0.5 * h);
    const HeldLagWeights w = HeldLagWeights::make(foh, kBeta, a, 0.0, 10.0, 0.5 * h);
    EXPECT_LT(std::abs(w.step(0.0, foh.phi, e.tbar, end.tbar) - end.filtered),
              1e-6 * std::abs(foh.foh(0.0, e.tbar, end.tbar) - end.filtered));
  }
}

// Without heating over the interval T̄ only decays: the weights take the lag's own shape, and
// with θ̂5 still 0 (the estimator's start) they stay finite and exact for a ramp.
TEST(HeldLag, CoolingAloneAndAZeroRateStayExact) {
  const double h = 0.01, a = 0.0594;
  const LagState start{4.0, 0.0};
  const LagState end = exact_piece(start, a, 1.0, 0.0, h);
  const HeldLagWeights cooling =
      HeldLagWeights::make(HoldCoefficients::make(kBeta, h), kBeta, a, 0.0, 0.0, 0.0);
  EXPECT_NEAR(cooling.step(0.0, std::exp(-kBeta * h), start.tbar, end.tbar), end.filtered, 1e-14);

  // a = 0, V² held at 2 with g = 1: T̄ is the ramp 1 + 2s, whose filter from y0 = 0 is
  // 1·(1 − e^{−βh}) + 2·(h − (1 − e^{−βh})/β).
  const HeldLagWeights ramp =
      HeldLagWeights::make(HoldCoefficients::make(kBeta, h), kBeta, 0.0, 2.0, 2.0, 0.3 * h);
  const double one_minus_phi = -std::expm1(-kBeta * h);
  const double expected = one_minus_phi + 2.0 * (h - one_minus_phi / kBeta);
  EXPECT_NEAR(ramp.step(0.0, 1.0 - one_minus_phi, 1.0, 1.0 + 2.0 * h), expected, 1e-15);
}

}  // namespace
}  // namespace scp::estimator

#pragma once
// β/(s+β) applied to T̄ over one sample interval under a held voltage, exactly.
//
// Between samples T̄ obeys dT̄/dt = −a·T̄ + θ6·V²(s) with a = θ5 and V² piecewise constant:
// V0² until the switch at `since` (s_s after the interval's start), V1² after it. Its path is
// then T̄(s) = T̄_k·e^{−as} + g·c(s), c(s) = ∫₀ˢ e^{−a(s−r)} V²(r) dr, and the end sample fixes
// g = (T̄_{k+1} − T̄_k·e^{−ah}) / c(h): only a = θ̂5 comes from the model, as in the quadratic
// `lag` correction this replaces, but the kink of T̄ at a switch inside the interval is now
// where it is: the lag without the kink left θ̂5, θ̂6 far outside the 1e-10 that
// tests/estimator/test_link_timing.cpp allows now (docs/numerics.md, "Filters"). With no heating
// over the interval (c(h) ≈ 0) the shape is the lag's, (1 − e^{−as})/(1 − e^{−ah}).
//
// The filtered step is linear in the end samples, y_{k+1} = φ·y_k + w_prev·T̄_k + w_next·T̄_{k+1},
// so one pair of weights serves every column built from T̄.

#include <algorithm>
#include <cmath>

#include "estimator/hold_filter.hpp"

namespace scp::estimator {

struct HeldLagWeights {
  double w_prev = 0.0;
  double w_next = 0.0;

  // `hold` for the same β and h; a ≥ 0; 0 ≤ switch_offset ≤ h (0: V1² over the whole interval,
  // a DAC that switched at the sample).
  static HeldLagWeights make(const HoldCoefficients& hold, double beta, double a, double v0_squared,
                             double v1_squared, double switch_offset) noexcept {
    const double h = hold.h;
    const double s_s = std::clamp(switch_offset, 0.0, h);
    const double decay_h_minus_one = std::expm1(-a * h);  // e^{−ah} − 1, exact for small ah
    const double lag_h = a * h > 1e-12 ? -decay_h_minus_one / a : h;           // E(h)
    const double filtered_decay = filtered_exponential(beta, a, h, hold.phi);  // of e^{−as}
    double filtered_shape;  // ∫ kernel · ψ, ψ = c(s)/c(h)
    if (s_s == 0.0) {
      // One V² over the interval (or none): ψ = E(s)/E(h) whatever V1² is, E(s) = (1 − e^{−as})/a.
      // The common case (a sample-synchronous DAC, every simulated run): two exponentials.
      filtered_shape = filtered_lag_integral(a, hold.zoh, filtered_decay, 1.0, beta, h) / lag_h;
    } else {
      // c(s) before the switch: V0²·E(s); after: V1²·E(s − s_s) + c_s·e^{−a(s−s_s)}.
      const double tail = h - s_s;
      const double c_switch = v0_squared * lag_integral(a, s_s);
      const double c_end = v1_squared * lag_integral(a, tail) + c_switch * std::exp(-a * tail);
      const double kernel_at_switch = std::exp(-beta * tail);
      if (c_end > 1e-12 * (v0_squared + v1_squared) * h) {
        const double ke_tail = filtered_exponential(beta, a, tail, kernel_at_switch);
        const double head =
            v0_squared *
            filtered_lag_integral(
                a, kernel_at_switch * -std::expm1(-beta * s_s),
                kernel_at_switch * filtered_exponential(beta, a, s_s, std::exp(-beta * s_s)),
                kernel_at_switch, beta, s_s);
        const double after = v1_squared * filtered_lag_integral(a, -std::expm1(-beta * tail),
                                                                ke_tail, 1.0, beta, tail) +
                             c_switch * ke_tail;
        filtered_shape = (head + after) / c_end;
      } else {  // no heating: the lag's own shape, as for s_s = 0
        filtered_shape = filtered_lag_integral(a, hold.zoh, filtered_decay, 1.0, beta, h) / lag_h;
      }
    }
    HeldLagWeights w;
    w.w_next = filtered_shape;
    w.w_prev = filtered_decay - (1.0 + decay_h_minus_one) * filtered_shape;
    return w;
  }

  double step(double y, double phi, double u_prev, double u_next) const noexcept {
    return phi * y + w_prev * u_prev + w_next * u_next;
  }

 private:
  // E(L) = (1 − e^{−aL})/a, → L as a → 0.
  static double lag_integral(double a, double length) noexcept {
    return a * length > 1e-12 ? -std::expm1(-a * length) / a : length;
  }
  // E(t) over a piece of length L, filtered: ∫ kernel·E = (∫ kernel − ∫ kernel·e^{−at}) / a from
  // the piece's two kernel integrals, or for a → 0 the filtered ramp, scaled by the kernel's
  // value at the piece's start.
  static double filtered_lag_integral(double a, double kernel_integral,
                                      double kernel_exponential_integral, double kernel_at_start,
                                      double beta, double length) noexcept {
    if (a * length > 1e-8) return (kernel_integral - kernel_exponential_integral) / a;
    return kernel_at_start * (length + std::expm1(-beta * length) / beta);
  }
  // ∫₀ᴸ β e^{−β(L−t)} e^{−a t} dt given e^{−βL}, without cancellation when a ≈ β.
  static double filtered_exponential(double beta, double a, double length,
                                     double kernel_decay) noexcept {
    const double x = (beta - a) * length;
    if (std::abs(x) < 1e-6) return beta * length * kernel_decay * (1.0 + 0.5 * x);
    return beta * kernel_decay * std::expm1(x) / (beta - a);
  }
};

}  // namespace scp::estimator

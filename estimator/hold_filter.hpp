#pragma once
// Exact discretization of the first-order low-pass β/(s+β) used by every filter of the paper
// (eqs. (9), (14), (15)) for the two ways a sampled input can behave between samples.
//
// First-order hold (FOH): the input is linear between u_k and u_{k+1}. Integrating
// ẏ = −βy + βu exactly over h gives, with φ = e^{−βh},
//   y_{k+1} = φ y_k + c0 u_k + c1 u_{k+1},  c0 = (1−φ)/(βh) − φ,  c1 = 1 − (1−φ)/(βh).
// It is exact for ramps; for a smooth input the local error is O(h³) (global O(h²)). Holding
// the measured signals constant instead (ZOH) leaves a bias in θ̂ four orders of magnitude larger
// (PAPER-NOTES).
//
// Quadratic correction (what the estimator uses once three samples are known): FOH alone leaves
// a global error ≈ −(h²/12)·F[u''], and in the mechanical row the stiffness term multiplies it by
// k/m ≈ 1813 s⁻², a relative error (h²/12)·k/m ≈ 1.5e-4 of a_f in the "mass" direction at 1 kHz,
// which biases every mechanical θ̂ᵢ as much (docs/numerics.md, "Filters"). Interpolating through
// u_{k−1}, u_k,
// u_{k+1} adds J·q to the FOH step, with q the second divided difference and
//   J = ∫₀ʰ β e^{−β(h−s)} s(s−h) ds = −((h − 2/β)·I1 + h²φ),  I1 = (1−φ)/β − hφ,
// which makes the step exact for quadratics (local error O(h⁴), global O(h³)).
//
// Zero-order hold (ZOH): the input is constant at u_{k+1} over (t_k, t_{k+1}] — exactly what a
// DAC does with the voltage — so y_{k+1} = φ y_k + (1−φ) u_{k+1}, exact for that input.

#include <cmath>

namespace scp::estimator {

struct HoldCoefficients {
  double phi = 1.0;  // e^{−βh}
  double c0 = 0.0;   // weight of u_k (FOH)
  double c1 = 0.0;   // weight of u_{k+1} (FOH)
  double zoh = 0.0;  // 1 − φ, weight of u_{k+1} (ZOH)
  double h = 0.0;    // s
  double j = 0.0;    // J, weight of the second divided difference (quadratic correction)

  // beta > 0, h > 0. expm1 keeps 1 − φ accurate when βh is small (βh = 3e-3 at 1 kHz).
  static HoldCoefficients make(double beta, double h) noexcept {
    const double bh = beta * h;
    const double one_minus_phi = -std::expm1(-bh);
    const double ratio = one_minus_phi / bh;  // (1−φ)/(βh), in (0, 1)
    HoldCoefficients c;
    c.phi = 1.0 - one_minus_phi;
    c.c0 = ratio - c.phi;
    c.c1 = 1.0 - ratio;
    c.zoh = one_minus_phi;
    c.h = h;
    if (bh < 1e-2) {
      // The closed form cancels badly for small βh; its series Σ (−βh)ⁿ/(n!(n+2)(n+3)) does not.
      c.j =
          -beta * h * h * h *
          (1.0 / 6.0 + bh * (-1.0 / 12.0 + bh * (1.0 / 40.0 + bh * (-1.0 / 180.0 + bh / 1008.0))));
    } else {
      const double i1 = one_minus_phi / beta - h * c.phi;
      c.j = -((h - 2.0 / beta) * i1 + h * h * c.phi);
    }
    return c;
  }

  double foh(double y, double u_prev, double u_next) const noexcept {
    return phi * y + c0 * u_prev + c1 * u_next;
  }
  // u0 = u_{k−1} at t_k − h0, u1 = u_k, u2 = u_{k+1} at t_k + h.
  double quadratic(double y, double u0, double u1, double u2, double h0) const noexcept {
    const double q = ((u2 - u1) / h - (u1 - u0) / h0) / (h + h0);
    return foh(y, u1, u2) + j * q;
  }
  double zoh_step(double y, double u_next) const noexcept { return phi * y + zoh * u_next; }
  // ZOH with the input switching inside the interval: u_prev until `tail` before its end, u_next
  // for the last `tail` seconds (0 < tail < h) — a DAC whose command arrived mid-interval. Exact:
  // y_{k+1} = φ y_k + (e^{−β·tail} − φ) u_prev + (1 − e^{−β·tail}) u_next.
  double zoh_split_step(double y, double u_prev, double u_next, double beta,
                        double tail) const noexcept {
    const double late = -std::expm1(-beta * tail);  // 1 − e^{−β·tail}
    return phi * y + (zoh - late) * u_prev + late * u_next;
  }
};

}  // namespace scp::estimator

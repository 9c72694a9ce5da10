#pragma once
// The regression matrix W of eq. (6), such that a = [ẍ, dT̄/dt]ᵀ = W θ (eq. (8)):
//   W = [ −ẋ  −T̄ẋ  −x  −T̄   0    0 ]
//       [  0    0    0   0  −T̄   V² ]
// Row 1 touches only θ1..θ4 and row 2 only θ5, θ6; the estimator exploits this split.

#include "estimator/types.hpp"

namespace scp::estimator {

// xdot in m/s, tbar in °C above ambient, x in m, voltage in V.
inline Regressor regressor(double xdot, double tbar, double x, double voltage) noexcept {
  Regressor w;
  w << -xdot, -tbar * xdot, -x, -tbar, 0.0, 0.0,  //
      0.0, 0.0, 0.0, 0.0, -tbar, voltage * voltage;
  return w;
}

}  // namespace scp::estimator

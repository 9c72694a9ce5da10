// The Cramér–Rao bound of refine/fit.hpp: the same streamed JᵀWJ as the fit's, at the truth.
#include <cmath>

#include "refine/covariance.hpp"
#include "refine/fit.hpp"
#include "refine/residual_pass.hpp"

namespace scp::refine {

Matrix6 cramer_rao_bound(std::span<const WindowSample> window, const Vector6& theta,
                         const InitialState& initial, const Vector2& noise_sigma,
                         const std::array<bool, 6>& known) {
  Matrix6 bound = Matrix6::Zero();
  if (window.size() < 2 || !theta.allFinite() || !initial.allFinite()) return bound;
  Vector9 p;
  p << theta, initial;
  PassSettings ps;
  for (int c = 0; c < 2; ++c) {
    const double s = noise_sigma[c];
    ps.weight[c] = std::isfinite(s) && s > 0.0 ? 1.0 / (s * s) : 0.0;
  }
  const PassResult pass = residual_pass(window, p, ps);
  FreeMask free{};
  for (int i = 0; i < 6; ++i) free[i] = !known[i];
  free[kX0] = free[kXdot0] = free[kTbar0] = true;
  Matrix9 inverse;
  if (!pass.finite || !inverse_on_free(pass.jtwj, free, inverse)) {
    bound.setConstant(std::numeric_limits<double>::infinity());
    return bound;
  }
  return inverse.topLeftCorner<6, 6>();
}

}  // namespace scp::refine

// The Cramér–Rao bound of refine/fit.hpp: the same streamed JᵀWJ as the fit's, at the truth.
#include <cmath>

#include "refine/covariance.hpp"
#include "refine/fit.hpp"
#include "refine/residual_pass.hpp"

namespace scp::refine {

Matrix6 cramer_rao_bound(std::span<const WindowSample> window, const Vector6& theta,
                         const InitialState& initial, const Vector2& noise_sigma,
                         const std::array<bool, 6>& known, const NuisanceSettings& nuisance,
                         const ExtensionSettings& extensions, const Tempcos& truth) {
  Matrix6 bound = Matrix6::Zero();
  if (window.size() < 2 || !theta.allFinite() || !initial.allFinite()) return bound;
  ParamVector p = param_vector(theta, initial);
  p[kResistanceTempcoSlot] = truth.rho;
  p[kStiffnessSofteningSlot] = truth.kappa;
  p[kCoolingTempcoSlot] = truth.gamma;
  p[kSensorLagSlot] = nuisance.sensor_lag.value;
  FreeMask free = free_slots(known, nuisance);
  free_extensions(extensions, free);
  PassSettings ps;
  ps.extensions = extensions.any();
  ps.sensor_lag = !nuisance.sensor_lag.fixed;
  for (int c = 0; c < 2; ++c) {
    const double s = noise_sigma[c];
    ps.weight[c] = std::isfinite(s) && s > 0.0 ? 1.0 / (s * s) : 0.0;
  }
  const PassResult pass = residual_pass(window, p, ps);
  ParamMatrix inverse;
  if (!pass.finite || !inverse_on_free(pass.jtwj, free, inverse)) {
    bound.setConstant(std::numeric_limits<double>::infinity());
    return bound;
  }
  return inverse.topLeftCorner<kThetaSize, kThetaSize>();
}

}  // namespace scp::refine

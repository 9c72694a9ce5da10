// The Cramér–Rao bound of refine/fit.hpp: the same streamed JᵀWJ as the fit's, at the truth.
#include <cmath>

#include "refine/covariance.hpp"
#include "refine/fit.hpp"
#include "refine/residual_pass.hpp"
#include "refine/switch_placement.hpp"
#include "refine/voltage_timing.hpp"

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

namespace {

// The fit placed_switches_covariance reads, at the truth: its model, the slots a fit estimates
// (the nuisance terms `nuisance` leaves free, the extensions `extensions` does not leave off) and
// the noise.
FitResult fit_at_truth(const Vector6& theta, const InitialState& initial,
                       const Vector2& noise_sigma, const NuisanceSettings& nuisance,
                       const ExtensionSettings& extensions, const Tempcos& truth) {
  FitResult at;
  at.theta = theta;
  at.initial_state = initial;
  at.noise_sigma = noise_sigma;
  at.nuisance.x_zero.estimated = !nuisance.x_zero.fixed;
  at.nuisance.ambient_offset.estimated = !nuisance.ambient_offset.fixed;
  at.nuisance.ambient_drift.estimated = !nuisance.ambient_drift.fixed;
  at.nuisance.sensor_lag = {!nuisance.sensor_lag.fixed, nuisance.sensor_lag.value, 0.0};
  const double values[] = {truth.rho, truth.kappa, truth.gamma};
  for (std::size_t i = 0; i < kExtensionTable.size(); ++i) {
    const ExtensionSlot& e = kExtensionTable[i];
    ExtensionEstimate& out = at.extensions.*e.estimate;
    out.mode = extensions.*e.mode;
    out.kept = out.mode != ExtensionMode::off;
    out.value = values[i];
  }
  return at;
}

}  // namespace

Matrix6 switch_phases_bound_share(std::span<const WindowSample> window, const Vector6& theta,
                                  const InitialState& initial, const Vector2& noise_sigma,
                                  const std::array<bool, 6>& known,
                                  const NuisanceSettings& nuisance,
                                  const ExtensionSettings& extensions, const Tempcos& truth,
                                  std::size_t& switches) {
  switches = 0;
  if (window.size() < 3 || !theta.allFinite() || !initial.allFinite()) return Matrix6::Zero();
  std::vector<WindowSample> storage;
  const std::span<const WindowSample> prepared =
      prepare_window(window, estimator::VoltageHold::foh, VoltageInterval::before, storage,
                     VoltageShape::smooth, 0.5);
  switches = count_voltage_switches(prepared);
  if (switches == 0) return Matrix6::Zero();
  const FitResult at = fit_at_truth(theta, initial, noise_sigma, nuisance, extensions, truth);
  return placed_switches_covariance(prepared, at, known);
}

}  // namespace scp::refine

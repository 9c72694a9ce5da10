// The Cramér–Rao bound of refine/fit.hpp: the same streamed JᵀWJ as the fit's, at the truth.
#include <cmath>

#include "refine/covariance.hpp"
#include "refine/fit.hpp"
#include "refine/input_delay.hpp"
#include "refine/residual_pass.hpp"
#include "refine/switch_placement.hpp"
#include "refine/voltage_delay_bound.hpp"
#include "refine/voltage_timing.hpp"

namespace scp::refine {

namespace {

// The bound's pass at the truth: its parameter vector, the slots a fit estimates and the pass's
// weights (the channels' noise).
struct BoundSetup {
  ParamVector p = ParamVector::Zero();
  FreeMask free{};
  PassSettings pass;
};

BoundSetup bound_setup(const Vector6& theta, const InitialState& initial,
                       const Vector2& noise_sigma, const std::array<bool, 6>& known,
                       const NuisanceSettings& nuisance, const ExtensionSettings& extensions,
                       const Tempcos& truth) {
  BoundSetup out;
  out.p = param_vector(theta, initial);
  out.p[kResistanceTempcoSlot] = truth.rho;
  out.p[kStiffnessSofteningSlot] = truth.kappa;
  out.p[kCoolingTempcoSlot] = truth.gamma;
  out.p[kSensorLagSlot] = nuisance.sensor_lag.value;
  out.free = free_slots(known, nuisance);
  free_extensions(extensions, out.free);
  out.pass.extensions = extensions.any();
  out.pass.sensor_lag = !nuisance.sensor_lag.fixed;
  for (int c = 0; c < 2; ++c) {
    const double s = noise_sigma[c];
    out.pass.weight[static_cast<std::size_t>(c)] =
        std::isfinite(s) && s > 0.0 ? 1.0 / (s * s) : 0.0;
  }
  return out;
}

}  // namespace

Matrix6 cramer_rao_bound(std::span<const WindowSample> window, const Vector6& theta,
                         const InitialState& initial, const Vector2& noise_sigma,
                         const std::array<bool, 6>& known, const NuisanceSettings& nuisance,
                         const ExtensionSettings& extensions, const Tempcos& truth) {
  Matrix6 bound = Matrix6::Zero();
  if (window.size() < 2 || !theta.allFinite() || !initial.allFinite()) return bound;
  const BoundSetup setup =
      bound_setup(theta, initial, noise_sigma, known, nuisance, extensions, truth);
  const PassResult pass = residual_pass(window, setup.p, setup.pass);
  ParamMatrix inverse;
  if (!pass.finite || !inverse_on_free(pass.jtwj, setup.free, inverse)) {
    bound.setConstant(std::numeric_limits<double>::infinity());
    return bound;
  }
  return inverse.topLeftCorner<kThetaSize, kThetaSize>();
}

VoltageDelayBound voltage_delay_bound(std::span<const WindowSample> window, const Vector6& theta,
                                      const InitialState& initial, const Vector2& noise_sigma,
                                      const std::array<bool, 6>& known,
                                      const NuisanceSettings& nuisance,
                                      const ExtensionSettings& extensions, const Tempcos& truth) {
  VoltageDelayBound out;
  if (window.size() < 3 || !theta.allFinite() || !initial.allFinite()) return out;
  const double h = latest_switch_delay(window, 1.0) / 20.0;
  if (!(h > 0.0)) return out;
  BoundSetup setup = bound_setup(theta, initial, noise_sigma, known, nuisance, extensions, truth);
  std::array<PassResult, 3> at;  // d = 0, h, 2h: one-sided, a switch cannot move before its sample
  for (std::size_t i = 0; i < at.size(); ++i) {
    setup.pass.input_delay = static_cast<double>(i) * h;
    at[i] = residual_pass(window, setup.p, setup.pass);
    if (!at[i].finite) return out;
  }
  ParamMatrix inverse;
  if (!inverse_on_free(at[0].jtwj, setup.free, inverse)) return out;
  // b = J_pᵀW J_d from the score's slope, c = J_dᵀW J_d from the cost's curvature (both second
  // order in h; the residuals at the truth are the plant's discretization's, near 0).
  const ParamVector b = (-3.0 * at[0].jtwr + 4.0 * at[1].jtwr - at[2].jtwr) / (2.0 * h);
  const double c = (at[0].cost - 2.0 * at[1].cost + at[2].cost) / (2.0 * h * h);
  const ParamVector g = inverse * b;
  const double schur = c - b.dot(g);
  if (!(schur > 0.0) || !std::isfinite(schur) || !g.allFinite()) return out;
  out.ok = true;
  out.delay_sigma_s = 1.0 / std::sqrt(schur);
  out.theta_per_second = g.head<kThetaSize>();
  out.share = out.theta_per_second * out.theta_per_second.transpose() / schur;
  return out;
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

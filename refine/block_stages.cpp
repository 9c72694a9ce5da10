// The stages that fit one block of the model on its own channel (refine/stages.hpp): thermal
// on T̄, mechanical on x.
#include <algorithm>

#include "refine/stages.hpp"

namespace scp::refine {

FreeMask thermal_slots(const std::array<bool, kThetaSize>& known) {
  FreeMask free{};
  for (const int i : kThermalTheta) free[i] = !known[i];
  free[kTbar0] = true;
  return free;
}

FreeMask thermal_slots(const FitSettings& settings) {
  FreeMask free = thermal_slots(settings.known);
  free[kAmbientOffsetSlot] = !settings.nuisance.ambient_offset.fixed;
  free[kAmbientDriftSlot] = !settings.nuisance.ambient_drift.fixed;
  FreeMask extensions{};
  free_extensions(settings.extensions, extensions);
  free[kResistanceTempcoSlot] = extensions[kResistanceTempcoSlot];
  free[kCoolingTempcoSlot] = extensions[kCoolingTempcoSlot];
  free[kSensorLagSlot] = !settings.nuisance.sensor_lag.fixed;
  return free;
}

PassSettings thermal_pass_settings() {
  PassSettings ps;
  ps.weight = {0.0, 1.0};
  ps.thermal_only = true;
  return ps;
}

PassSettings thermal_pass_settings(const FitSettings& settings) {
  PassSettings ps = thermal_pass_settings();
  carry_optional_slots(settings, ps);
  return ps;
}

FreeMask fit_slots(const FitSettings& settings) {
  FreeMask free = free_slots(settings.known, settings.nuisance);
  free_extensions(settings.extensions, free);
  return free;
}

FreeMask mechanical_slots(const std::array<bool, kThetaSize>& known) {
  FreeMask free{};
  for (const int i : kMechanicalTheta) free[i] = !known[i];
  free[kX0] = free[kXdot0] = true;
  return free;
}

FreeMask mechanical_slots(const FitSettings& settings) {
  FreeMask free = mechanical_slots(settings.known);
  free[kXZeroSlot] = !settings.nuisance.x_zero.fixed;
  free[kStiffnessSofteningSlot] = settings.extensions.stiffness_softening != ExtensionMode::off;
  return free;
}

StopReason fit_thermal(FitContext& ctx, FitState& state) {
  const Coordinates c(thermal_slots(ctx.settings), state.p);
  const StageResult r =
      run_stage(ctx.window, c, thermal_pass_settings(ctx.settings), ctx.max_iterations, ctx.budget);
  state.iterations += r.iterations;
  if (r.pass.finite) {
    state.p = r.p;
    state.noise.tbar =
        std::max(r.pass.rss[1] / dof(ctx.window.size(), c.index.size()), ctx.variance_floor[1]);
    state.range = {r.pass.tbar_min, r.pass.tbar_max};
    state.thermal = r.pass;
  }
  return r.stopped ? ctx.budget.stop() : StopReason::none;
}

StopReason fit_mechanical(FitContext& ctx, FitState& state) {
  const Coordinates c(mechanical_slots(ctx.settings), state.p);
  PassSettings ps;
  ps.weight = {1.0, 0.0};
  carry_optional_slots(ctx.settings, ps);
  const StageResult r = run_stage(ctx.window, c, ps, ctx.max_iterations, ctx.budget, state.range);
  state.iterations += r.iterations;
  if (r.pass.finite) {
    state.p = r.p;
    state.noise.x =
        std::max(r.pass.rss[0] / dof(ctx.window.size(), c.index.size()), ctx.variance_floor[0]);
  }
  return r.stopped ? ctx.budget.stop() : StopReason::none;
}

}  // namespace scp::refine

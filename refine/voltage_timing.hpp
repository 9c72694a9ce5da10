#pragma once
// The voltage's timing relative to the samples (FitSettings::voltage_hold, voltage_interval), put
// into the window once before the fit, so that the model's simulation and everything that rides
// on it (sensitivities, covariance, validation) keep their one convention: WindowSample's, the
// voltage held over the interval before its sample.
//
// - VoltageInterval::after (a log that writes the command issued at t): row k's voltage is moved
//   to row k + 1 with voltage_since = t_k, so it drives (t_k, t_{k+1}].
// - VoltageHold::foh (V varying continuously, each row's V the value at its instant; with `after`
//   the value reached at the next instant): V is linear between the rows, V² quadratic
//   (WindowSample::voltage_ramp), and the model integrates it exactly (ThermalPiece), the
//   mechanical block seeing T̄'s exact mean over each piece.

#include <array>
#include <span>
#include <vector>

#include "refine/fit.hpp"
#include "refine/voltage_switches.hpp"

namespace scp::refine {

// Whether the model reads a window as recorded under `hold` and `interval`: zoh and the interval
// before. Otherwise prepare_window needs storage for a copy (for `estimate`, if it chooses after).
constexpr bool reads_as_recorded(estimator::VoltageHold hold, VoltageInterval interval) noexcept {
  return hold == estimator::VoltageHold::zoh && interval == VoltageInterval::before;
}

// `window` as the model reads it under `hold` and `interval` (before or after), and with foh
// `shape` (smooth: with its switches held at `switch_phase`, hold_voltage_switches): `window`
// itself when it reads_as_recorded and has no currents, else `storage` filled and returned. With
// the heater's current in every sample, each row's voltage becomes its heating voltage, whose
// square is the measured power times R_ref (refine/heater_power.hpp).
std::span<const WindowSample> prepare_window(std::span<const WindowSample> window,
                                             estimator::VoltageHold hold, VoltageInterval interval,
                                             std::vector<WindowSample>& storage,
                                             VoltageShape shape = VoltageShape::linear,
                                             double switch_phase = 0.0);

// VoltageHold::foh with VoltageShape::smooth: each interval's midpoint voltage
// (WindowSample::voltage_mid) from the cubic through the rows before and after it, where the four
// are equally spaced (within 1e-6 of a period): V² is then exact to O(Δ⁴·V'''') where the chord's
// V² is off by Δ²·V''/8 (of V·V''). On a continuous voltage that difference is what the inertia of
// θ1..θ4 (a 0.8 ms lag between heating and motion) sees: docs/numerics.md, "The voltage's timing".
// prepare_window calls it; the rows at a window's ends and beside a gap or a switch keep the
// chord. Wrong for a DAC that ramps linearly between commands (VoltageShape::linear), whose slope
// changes at every row.
void add_cubic_midpoints(std::span<WindowSample> window) noexcept;

// Row `cur` as the model reads it under `hold` and `interval` (before or after), `prev` the row
// recorded before it: what prepare_window makes of every row but the first (without the cubic
// midpoints, which need the rows around it: a warm start's shift steps with the chord).
WindowSample prepared_sample(const WindowSample& prev, const WindowSample& cur,
                             estimator::VoltageHold hold, VoltageInterval interval) noexcept;

// A lag this many sampling periods long or shorter is what a one-period shift of the voltage
// looks like in T̄ (to first order), not a sensor's.
inline constexpr double kShiftLikeLagPeriods = 3.0;

// VoltageInterval::estimate: before or after, whichever gives the thermal stage's fit (θ5, θ6,
// T̄0 on T̄ alone, from `theta_start` as fit() starts) the lower Schwarz criterion, an estimated
// sensor lag tried both free and held at 0 (a one-period shift trades against it). A free lag
// that wins at a few periods or less is the other interval in disguise: the choice is then the
// held fits'. A real lag leaves the interval to the second-order term, and `after` must beat
// `before` by one slot's price. A row's interval is a whole sample period of the voltage's timing,
// which T̄ resolves to a fraction of a µs (refine/input_delay.hpp); x could not tell (θ1..θ4's
// common scale is a sub-millisecond lag). `before` when neither can be fitted.
// Where in their intervals a smooth voltage's switches fell (hold_voltage_switches): of the phases
// kSwitchPhases, the one whose thermal fit (θ5, θ6, T̄0 on T̄, the sensor lag held at `settings`'
// or 0) has the least residual variance. A switch's heat moves by (B² − A²)·Δ·θ6 across its
// interval, alternating in sign: T̄ resolves it where the switches are many (hundreds in 300 s of a
// 1 s PRBS) and the sensor fine. Phase 0 and no evaluation where there are no switches.
inline constexpr std::array<double, 3> kSwitchPhases{0.0, 0.5, 1.0};

SwitchPhase choose_switch_phase(std::span<const WindowSample> window, VoltageInterval interval,
                                const Vector6& theta_start, const FitSettings& settings);

VoltageInterval choose_voltage_interval(std::span<const WindowSample> window,
                                        const Vector6& theta_start, const FitSettings& settings);

// choose_voltage_interval's choice and how far the criterion decided it (IntervalEvidence: below
// its threshold the interval is undetermined, and the fit's θ1..θ4 are a guess's).
struct IntervalChoice {
  VoltageInterval interval = VoltageInterval::before;
  IntervalEvidence evidence;
  SwitchPhase switches;        // of a foh smooth voltage's switches under `interval`
  SwitchPhase other_switches;  // the same under the other interval
};
IntervalChoice weigh_voltage_interval(std::span<const WindowSample> window,
                                      const Vector6& theta_start, const FitSettings& settings);

}  // namespace scp::refine

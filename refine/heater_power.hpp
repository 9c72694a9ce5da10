#pragma once
// The heater's measured current (WindowSample::current, where the DAQ measures it): the thermal
// block's input becomes the measured power V·I instead of V²/R, so that a resistance that changes
// with temperature (or with age, or a contact's) is in the data rather than in the model.
//
//   Cth dT̄/dt = −λ T̄ + V·I        instead of        Cth dT̄/dt = −λ T̄ + V²/R
//
// The model keeps one input convention (the square of a per-row "voltage", model_simulator.hpp):
// a row's heating voltage becomes √(R_ref·V·I), whose square is R_ref times the measured power,
// and the fit's sixth slot is then 1/(R_ref·Cth). R_ref is the window's own resistance at the
// recorded T̄ = 0 (reference_resistance), so the slot starts near θ6. After the fit, R = V/I is
// regressed on the true T̄ (the measured one less the fit's ambient offset, drift and sensor lag):
// R0 at the true ambient, its ρ and their σ, and θ6 = 1/(R0·Cth) = slot·R_ref/R0 is published, so
// θ means what the paper means. The resistance_tempco extension is then not needed (fit() leaves
// it off): the power already carries R(T̄).

#include <cstddef>
#include <span>

#include "refine/fit.hpp"

namespace scp::refine {

// Rows on each side of a row whose currents give its conductance (use_measured_power).
inline constexpr std::size_t kConductanceHalfWidth = 16;

// True when every sample of the window has a finite current; a window with some currents missing
// is fitted from V²/R as if none were measured (the daemon faults on a non-finite current once a
// driver delivered one, so its windows are all or nothing).
bool measures_current(std::span<const WindowSample> window) noexcept;

// R(T̄) = R0·(1 + ρ·T̄) by least squares of V = I·R0 + I·T̄·R0ρ over the rows, each row's current
// paired with the voltage that drove it (the row's, or with VoltageInterval::after the row
// before's). `tbar_shift` and `drift`: T̄_true = T̄_recorded − tbar_shift − drift·(t − t0) +
// lag·dT̄/dt (the fit's nuisance terms; zero for the recorded T̄). A non-finite r0 when the
// currents carry no information (no heating).
HeaterResistance regress_resistance(std::span<const WindowSample> window, VoltageInterval interval,
                                    const Nuisance& nuisance = {});

// R_ref of the heating voltage: R0 regressed on the recorded T̄; 1 Ω when that is not usable.
double reference_resistance(std::span<const WindowSample> window, VoltageInterval interval);

// Rows prepared for the model (each row's voltage the one that drove its current, as the
// voltage's timing left them) given their heating voltages: |V|·√(r_ref·G), G the conductance I/V
// by least squares over the rows within ±half_width, for a held voltage the mean of G at its
// interval's two ends. The current's noise would enter the model as heating noise that the thermal
// block integrates into a coloured T̄ error; G changes only with T̄, over seconds, so averaging it
// over a few tens of milliseconds takes that noise out at no cost.
void use_measured_power(std::span<WindowSample> rows, double r_ref,
                        std::size_t half_width = kConductanceHalfWidth);

// After the fit of a window with currents: R0 and ρ on the fit's true T̄, θ6 = slot·R_ref/R0 with
// the covariance's row and column scaled alike and R0's variance added to θ6's.
void publish_measured_power(std::span<const WindowSample> window, FitResult& result);

}  // namespace scp::refine

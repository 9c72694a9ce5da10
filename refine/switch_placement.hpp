#pragma once
// Where in its interval each switch of a smooth voltage fell, from the fit's residuals.
//
// hold_voltage_switches (refine/voltage_switches.hpp) puts every switch at one phase, which fits a
// generator on the DAQ's clock. A generator on a clock of its own (a crystal tens of ppm off the
// DAQ's) puts each switch somewhere else between two rows, and a switch a fraction δ of its
// interval Δ later than modelled moves θ6·(A² − B²)·δ·Δ of heat: a step in T̄ that lasts the
// thermal time constant, and through the thermal force a step in x. Over 1 s bits of a few volts
// that is several times N1's noise, seconds long, at every switch.
//
// Each switch's step is the thermal block's impulse response, the same for every δ, so the phases
// are a linear least-squares problem on the residuals of a fitted model: the columns are the model
// linearised about its trajectory (T̄'s decay at the local cooling and heating slopes, the
// sensor's lag, x following T̄ through the mechanical block linearised about its x, ẋ and T̄),
// weighted by the channels' noise. θ is not held: a shift of every switch together
// trades with θ1..θ4's common scale (a sub-millisecond lag between heating and motion), so the
// step is Gauss–Newton's for the phases with the fit's free slots profiled out (the Schur
// complement of their information, which one forward sweep of the fitted model's sensitivities
// gives), and the fit is then made again at the new phases. The normal equations are solved by
// conjugate gradients; a switch's perturbation is a fixed 2×2 image of its start, so the sweep
// sums the linear model once per stretch between two switch rows and each product is a forward
// and a backward pass over the stretches.
// Each phase has the prior of a switch anywhere in its interval (variance 1/12 about where it
// is), so a switch the data cannot place stays put.
// refine/fit.cpp alternates this with the fit of θ.

#include <array>
#include <cstddef>
#include <span>
#include <vector>

#include "refine/fit.hpp"

namespace scp::refine {

struct SwitchPlacement {
  std::size_t placed = 0;        // switch rows given a phase of their own (all, or none)
  double largest_move = 0.0;     // the largest change of a phase, in intervals
  double rms_phase_sigma = 0.0;  // the phases' RMS standard deviation, in intervals
  // The weighted cost the step takes off (Gauss–Newton's prediction for the step with each phase
  // kept inside its interval: bᵀδ where none met an end) and what Schwarz's
  // criterion charges the phases for it (ln n each): with FirstStep::needs_evidence, a step that
  // takes off less moves nothing (placed = 0): one phase for all switches fits as well.
  double decrease = 0.0;
  double price = 0.0;
  // The step would take off less than the caller's settled decrease: nothing moved (`placed` still
  // counts the switches), and the sweep that showed it gave placed_switches_covariance's share at
  // the fit.
  bool settled = false;
  Matrix6 covariance_share = Matrix6::Zero();
};

// The first step of a fit decides whether the switches need a phase each; the later ones follow.
enum class PlacementStep : bool { needs_evidence, follows };

// Moves voltage_since of every switch row of `prepared` (a foh, smooth window after
// prepare_window: the rows hold_voltage_switches held, which `fit` fitted; `known` its fixed θ) to
// where the fit's residuals place it, within its interval. Allocates O(switches); leaves `prepared`
// as it was when it has no switch, more than kMostPlacedSwitches, the step is not finite, (the
// first step) the data do not ask for it, or (settled_decrease > 0) the step would take off less
// than settled_decrease.
SwitchPlacement place_voltage_switches(std::span<WindowSample> prepared, const FitResult& fit,
                                       const std::array<bool, 6>& known, PlacementStep step,
                                       double settled_decrease = 0.0);

// What the placed phases add to θ's covariance. They are unknowns estimated beside θ, so θ's
// covariance is the free slots' block of (A − Cᵀ N⁻¹ C)⁻¹ = A⁻¹ + A⁻¹Cᵀ S⁻¹ C A⁻¹ (A = JᵀWJ of
// the free slots, C = HᵀWJ, N the phases' information with their prior, S = N − C A⁻¹ Cᵀ); this is
// the second term's θ block, at `fit` on `prepared` as it placed them. Zero where nothing is
// placed.
Matrix6 placed_switches_covariance(std::span<const WindowSample> prepared, const FitResult& fit,
                                   const std::array<bool, 6>& known);

// What switches at phases of their own (a generator on a clock of its own) add to the Cramér–Rao
// bound of θ: cramer_rao_bound's experiment (`window` as recorded, read with foh, its switches
// held at mid-interval), the phases unknowns beside θ with their prior, as
// placed_switches_covariance counts them at a fit. `switches`: how many the window has. Zero
// where it has none to place.
Matrix6 switch_phases_bound_share(std::span<const WindowSample> window, const Vector6& theta,
                                  const InitialState& initial, const Vector2& noise_sigma,
                                  const std::array<bool, 6>& known,
                                  const NuisanceSettings& nuisance,
                                  const ExtensionSettings& extensions, const Tempcos& truth,
                                  std::size_t& switches);

// The weighted cost that placing the switches anew would take off `fit` on `prepared` (the
// decrease of place_voltage_switches' step, nothing moved; 0 where it would place nothing): what a
// model would gain from phases of its own, where `prepared`'s were placed for another.
double placement_decrease(std::span<const WindowSample> prepared, const FitResult& fit,
                          const std::array<bool, 6>& known);

// The switch rows of `prepared` (a foh, smooth window after prepare_window) where they now fall.
std::vector<PlacedSwitch> placed_switches(std::span<const WindowSample> prepared);

// Puts each switch row of `prepared` whose t is among `placed` (sorted by t) where `placed` has
// it; the others stay where prepare_window put them. Returns how many rows it moved.
std::size_t restore_placed_switches(std::span<WindowSample> prepared,
                                    std::span<const PlacedSwitch> placed);

// The phases' prior: a switch anywhere in its interval, variance 1/12.
inline constexpr double kSwitchPhasePriorPrecision = 12.0;
// More switches than this are left where they are: a drive switching every few periods gives each
// switch too little heat to place (its phases' errors average out instead).
inline constexpr std::size_t kMostPlacedSwitches = 4000;

}  // namespace scp::refine

#pragma once
// Stage (a') of the fit (refine/fit.cpp), with FitSettings::max_input_delay_s: the voltage's delay
// d relative to its recorded instants, from T̄ alone. The common scale of θ1..θ4 is a
// sub-millisecond lag between heating and motion, so x cannot tell it from a delay of the
// voltage; T̄'s response to V² has no fast pole and can. The thermal stage's cost is profiled
// along d ((θ5, θ6, T̄0) refitted at each d), minimized by golden section over [−limit, limit],
// then σ_d comes from its curvature (Δχ² = 1) and is checked by batch means
// (refine/delay_batch_means.hpp). Every later pass switches the voltage d later than recorded.

#include <span>

#include "refine/fit_state.hpp"

namespace scp::refine {

// The profile's minimum and σ_d from a start whose thermal part the thermal stage fitted. Its
// passes are thermal-only and count against a budget of their own, so that a fit with a delay to
// find has the same budget left for θ1..θ4 as one without.
InputDelayEstimate estimate_input_delay(const FitContext& ctx, const ParamVector& start);

// The stage: d estimated and applied to every later pass (StopReason::none), or why the fit
// ends (cancelled; no d without heating). Does nothing without FitSettings::max_input_delay_s.
StopReason fit_input_delay(FitContext& ctx, FitState& state);

// How far before its recorded instant a switch can be moved (a negative delay): as far as the
// earliest switch recorded inside its interval allows, at most `limit`. A DAC that switches at
// the samples records its switches there, and one cannot move into the interval before (the
// command was computed from that sample: causality says d ≥ 0 there).
double earliest_switch_delay(std::span<const WindowSample> window, double limit);

// How far after its recorded instant a switch can be moved and still mean something: the model
// holds a switch moved past its interval's end at that end (pieces_between), so every longer delay
// is the same model (a plateau the search must not wander onto: noise-free, a 5 ms limit at 1 kHz
// left it there, "could not be estimated"). The median room from the recorded switch (or the
// previous sample) to the interval's end, at most `limit`. A delay of a whole period or more is
// the voltage interval's business (FitSettings::voltage_interval).
double latest_switch_delay(std::span<const WindowSample> window, double limit);

}  // namespace scp::refine

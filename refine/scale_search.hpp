#pragma once
// Stage (b) of the fit (refine/fit.cpp): the common scale s of θ1..θ4. Scaling θ1..θ4 together
// changes only the weight of the inertia term (the fast pole), the direction the data determine
// worst and the one along which a biased start is off (the paper's law under noise lands at a
// fraction of the true scale). A search on the scale means something only once the ratios are
// right, so first (b1) the ratios θ1, θ2, θ4 (θ3 held) with x0, ẋ0 are fitted at 30× the
// start's scale, where the model is quasi-static (inertia negligible, the fast pole 30× further)
// and the ratios are all the data can see; then (b2) a 1-D search on ln s over [1/900, 1] of
// that: a grid at factors of 2, then golden section around its best point (cost-only passes). A
// start that fits better than what the search found is kept.
//
// Both searches only need to land in the basin of the mechanical stage: they run on the window's
// first kScaleSearchSeconds.

#include "refine/fit_state.hpp"

namespace scp::refine {

inline constexpr double kScaleSearchSeconds = 60.0;

// The stage: state.p's θ1..θ4 scaled (StopReason::none), or why the fit ends (cancelled, budget
// spent). Does nothing when a mechanical parameter is known: there is no common scale to search.
StopReason search_scale(FitContext& ctx, FitState& state);

// A start whose damping θ1 + θ2·T̄ turns negative somewhere in the thermal stage's T̄ range cannot
// be simulated (the paper's law under noise can give such θ̂, and every stage then stops at its
// start). θ2 is a small modulation of the damping: such a start drops it (unless known) and lets
// the fit find it.
void start_with_positive_damping(const FitContext& ctx, FitState& state);

}  // namespace scp::refine

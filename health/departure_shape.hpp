#pragma once
// Is a fast alarm's departure a step or the start of a ramp (a drift that the trend reference has
// not caught up with)? Each score block's single-parameter estimate δ_b = s_b/I_b (weight I_b) is
// fitted, over a grid of onsets s, with three shapes:
//   step       ∆·[t ≥ s]
//   ramp       r·(t − s)⁺
//   jump+ramp  ∆·[t ≥ s] + r·(t − s)⁺
// A drift is continuous at its start and a step is not: the departure is a drift when the ramp
// fits better than the step AND adding a jump to the ramp does not fit significantly better.
// Both comparisons are in units of the residual scale σ̂² (≥ 1) of the jump+ramp fit: a large
// change leaves each block's δ_b off the linear model by the change's second-order term, which
// varies with the excitation from block to block, and then weighted residual sums are far above
// their χ² (the b/m +10 % of a daemon run: ~1e6 over ~200 blocks), so a fixed margin in absolute
// units would call whichever shape happens to bend with the misfit.

#include <span>

#include "health/score_blocks.hpp"

namespace scp::health {

struct ShapeFit {
  bool valid = false;
  double sse = 0.0;    // Σ I_b·(δ_b − model)² over every block given
  double onset = 0.0;  // s, the best s of the grid
  double jump = 0.0;   // ∆, θ units
  double slope = 0.0;  // r, θ units per second
};

struct DepartureShape {
  ShapeFit step, ramp, jump_ramp;
  int blocks = 0;            // blocks that observe the parameter
  double noise_scale = 1.0;  // σ̂² = max(1, jump_ramp.sse/(blocks − 3))

  // The ramp beats the step by `margin`·σ̂², and a jump in the departure's direction does not
  // improve the ramp by `margin`·σ̂² (χ²₁ quantiles are the natural margins).
  bool is_drift(double margin) const noexcept;
};

// `blocks` oldest first. The onsets searched are the blocks' starts from `search_before_s` before
// the CUSUM's change point `cusum_onset` to the newest block: the change point is the start of
// the block after the CUSUM last stood at zero, and a step inside that block (or, the CUSUM
// having crept up on noise, a few blocks later) must be found where it is, or the block that
// straddles it is forced onto the step's level and the step fits worse than a ramp.
DepartureShape fit_departure(std::span<const ScoreBlock> blocks, int parameter, double cusum_onset,
                             double search_before_s);

}  // namespace scp::health

#pragma once
// The batch-means check on the voltage's delay d (FitSettings::max_input_delay_s), which the fit
// profiles from T̄ alone and whose σ_d it takes from the profile's curvature: right when T̄'s
// residuals are white, too small when the landings' timing wanders slowly (a live link's landing
// stamps wander about the one constant d stands for: docs/numerics.md, "The delay's σ"). d moves
// θ6, so a σ_d too small is a θ6 σ too small.
//
// d's score, information and cross terms come from three thermal passes at the same (θ5, θ6, T̄0)
// with d at d̂ − h, d̂, d̂ + h, each summed over the same K batches (PassResult::batch_costs,
// batch_scores), per batch (refine/delay_differences.hpp).
// d is carried in a slot of p that the thermal stage leaves fixed, and the augmented scores and
// information go to check_against_batch_means (refine/covariance.hpp), against the white
// covariance: what it finds for that slot is d's own, the thermal parameters profiled out (their
// slow errors, which the same check sees on θ5, θ6 themselves, are not d's).

#include <cstddef>

#include "refine/covariance.hpp"
#include "refine/residual_pass.hpp"

namespace scp::refine {

// `below`, `at`, `above`: the passes at d̂ − h, d̂, d̂ + h (weights 1/σ², batches alike); `free`:
// the thermal stage's free coordinates, with `delay_slot` not among them. A check with factor 1
// everywhere when the batches are missing or do not match, or the information is not definite.
BatchMeansCheck check_delay_against_batch_means(const PassResult& below, const PassResult& at,
                                                const PassResult& above, double h, FreeMask free,
                                                std::size_t delay_slot);

}  // namespace scp::refine

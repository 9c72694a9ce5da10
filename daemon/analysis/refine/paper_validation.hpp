#pragma once
// The paper law's verdict (issue 28, "the paper law's block gets the same verdict from its own
// prediction"): its θ̂ simulated through the window the refinement fitted, the residuals tested
// as refine::validate_fit tests the refined fit's, but with no sensitivities projected off
// (jacobian_columns = 0: the paper law did not fit this window's output error), which makes every
// regression test conservative. One pass, off the loop thread.

#include <span>

#include "refine/fit.hpp"
#include "refine/validation.hpp"

namespace scp::daemon::refine {

// `initial`: the state the simulation starts from (the refined fit's, estimated on the same
// window; the paper law has none). `input_delay`: the voltage's delay the refined fit used.
scp::refine::ValidationReport validate_paper(std::span<const scp::refine::WindowSample> window,
                                             const scp::refine::Vector6& theta,
                                             const scp::refine::InitialState& initial,
                                             double input_delay,
                                             const scp::refine::Vector2& declared_noise);

}  // namespace scp::daemon::refine

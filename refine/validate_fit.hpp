#pragma once
// The validation (refine/validation.hpp) of a fit that has already returned: one more pass over
// the window at θ̂ with the fit's sensitivities, feeding the validator sample by sample. The fit's
// own final pass can feed it instead, at no extra simulation (docs/validation.md, "Hook").

#include <array>
#include <span>

#include "refine/fit.hpp"
#include "refine/validation.hpp"

namespace scp::refine {

// `settings` as given, except: time constants ≤ 0 come from θ̂ at the window's mean measured T̄
// (model_time_constants), and the sensitivities of the fit's nine free parameters (θ minus
// `known`, and the initial state) are projected off. The model is simulated as fit() does, with
// its estimated voltage delay; the timing-jitter and landing-filter weights of a link's fit are
// not reproduced (its residuals here are the plain simulation's).
// V² averaged over (prev.t, cur.t] as the model sees it (the pieces of pieces_between, the voltage
// switching `input_delay` later than recorded): the thermal block's input for a validation sample.
double mean_square_voltage(const WindowSample& prev, const WindowSample& cur,
                           double input_delay = 0.0) noexcept;

ValidationReport validate_fit(std::span<const WindowSample> window, const FitResult& fit,
                              ValidationSettings settings, const std::array<bool, 6>& known = {});

}  // namespace scp::refine

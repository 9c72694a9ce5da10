#pragma once
// The validation (refine/validation.hpp) of a fit that has already returned: one more pass over
// the window at θ̂ with the fit's sensitivities, feeding the validator sample by sample. The fit's
// own final pass can feed it instead, at no extra simulation (docs/validation.md, "Hook").

#include <array>
#include <optional>
#include <span>

#include "refine/fit.hpp"
#include "refine/parameters.hpp"
#include "refine/validation.hpp"

namespace scp::refine {

// The fitted error of the measured T̄ (refine::tbar_output): the model's own T̄ is the measured
// one less this, and the model's time constants are taken at the model's T̄.
struct AmbientError {
  double offset = 0.0;
  double drift_per_s = 0.0;  // from the window's first sample
};

// The validation's settings for the model at θ on `window`: `base` (declared noise, level, blocks,
// lags, floor, tests switched off) with its time constants ≤ 0 taken from θ at the window's mean
// T̄ as the model sees it (measured, less `ambient`; model_time_constants), and
// - with `free` (a fit's kParams sensitivities fed): the columns of the slots the fit held fixed
//   not projected off, and the targeted tests of the nuisance terms it estimated switched off;
// - without (std::nullopt: a prediction, e.g. the paper law's): no sensitivities.
// `window` as the model read it (a fit's: refine::prepare_window's output).
ValidationSettings validation_settings(std::span<const WindowSample> window, const Vector6& theta,
                                       const std::optional<FreeMask>& free,
                                       const ValidationSettings& base = {},
                                       const AmbientError& ambient = {});

// V² averaged over (prev.t, cur.t] as the model sees it (the pieces of pieces_between, the voltage
// switching `input_delay` later than recorded): the thermal block's input for a validation sample.
double mean_square_voltage(const WindowSample& prev, const WindowSample& cur,
                           double input_delay = 0.0) noexcept;

// `settings` completed by validation_settings() with the fit's free slots (θ minus `known`, the
// initial state, the nuisance terms it estimated): all kParams sensitivities are fed. The model is
// simulated as fit() does, with its estimated voltage delay; the timing-jitter and landing-filter
// weights of a link's fit are not reproduced (its residuals here are the plain simulation's).
// `window` must be the one the fit saw: refine::prepare_window's output, not the record, when the
// fit's voltage_interval is `after` (V moved one row later) or its hold `foh` (V ramped).
ValidationReport validate_fit(std::span<const WindowSample> window, const FitResult& fit,
                              ValidationSettings settings, const std::array<bool, 6>& known = {});

}  // namespace scp::refine

#pragma once
// Why a fit ended short of its verdict, or which check of the verdict failed; each with the one
// text the daemon logs and the protocol publishes (FitResult::message).

namespace scp::refine {

enum class StopReason {
  none,  // every stage ran and the verdict passed: the joint stage's solver says how it ended
  // The window (checked before anything runs).
  window_too_short,
  window_not_finite,
  window_times_not_increasing,
  start_not_finite,
  // The fit's bounds (FitSettings::cancel, max_evaluations and the work budget).
  cancelled,
  evaluation_budget_spent,
  work_budget_spent,
  // A stage that cannot go on.
  input_delay_not_estimated,
  model_not_finite,
  // From a model whose fast pole the sampling no longer resolves, the step leads to one too stiff
  // to simulate (refine/levenberg_marquardt.hpp, runs_past_resolution()).
  stalled,
  // The verdict on the solution, in the order it checks them.
  model_unstable,
  fast_pole_unresolved,
  covariance_singular,
  input_delay_at_limit,
};

// A static string; "" for none.
const char* to_text(StopReason reason) noexcept;

}  // namespace scp::refine

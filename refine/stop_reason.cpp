#include "refine/stop_reason.hpp"

namespace scp::refine {

const char* to_text(StopReason reason) noexcept {
  switch (reason) {
    case StopReason::none:
      return "";
    case StopReason::window_too_short:
      return "window has fewer than 3 samples";
    case StopReason::window_not_finite:
      return "window has a non-finite sample";
    case StopReason::window_times_not_increasing:
      return "window times are not strictly increasing";
    case StopReason::start_not_finite:
      return "start not finite";
    case StopReason::cancelled:
      return "cancelled";
    case StopReason::evaluation_budget_spent:
      return "evaluation budget spent (FitSettings::max_evaluations) before convergence";
    case StopReason::work_budget_spent:
      return "work budget spent: the model was too stiff to simulate";
    case StopReason::input_delay_not_estimated:
      return "the voltage's delay could not be estimated from T (no heating?)";
    case StopReason::model_not_finite:
      return "model not finite";
    case StopReason::stalled:
      return "stalled: the model does not explain the data (the fit runs to a fast mechanical "
             "pole beyond the sampling)";
    case StopReason::model_unstable:
      return "model unstable at the fit";
    case StopReason::fast_pole_unresolved:
      return "the fitted fast mechanical pole is far beyond the sampling: this window does not "
             "determine the common scale of theta1..theta4 (the inertia)";
    case StopReason::covariance_singular:
      return "covariance singular: a free parameter is not excited";
    case StopReason::input_delay_at_limit:
      return "the voltage's delay is at the search limit (FitSettings::max_input_delay_s): its "
             "timing is off by more than that";
  }
  return "";
}

}  // namespace scp::refine

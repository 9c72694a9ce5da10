#include "refine/budget.hpp"

#include <algorithm>
#include <cmath>

namespace scp::refine {

namespace {

// The work budget's model sub-steps per sample and pass, on average over the fit. 2 covers a fit
// at 1 kHz (the paper's fast pole: one sub-step per 1 ms interval) with room to spare. On a link
// the fit runs up to twice the joint stage's rounds, on intervals ten times longer cut in two at
// each landing, each piece into several sub-steps: 8 there (docs/numerics.md, "Figures behind the
// code comments").
long substeps_per_sample(const FitSettings& s) {
  return s.sample_timing_jitter ? 8 : 2;
}

}  // namespace

Budget::Budget(std::span<const WindowSample> window, const FitSettings& settings)
    : max_evaluations_(std::max(1, settings.max_evaluations)),
      max_substeps_(substeps_per_sample(settings) * static_cast<long>(max_evaluations_) *
                    static_cast<long>(window.size())),
      cancel_(settings.cancel) {
  const double span = window.back().t - window.front().t;
  mean_interval_ = span / static_cast<double>(window.size() - 1);
}

StopReason Budget::stop() const {
  if (cancel_ != nullptr && cancel_->load(std::memory_order_relaxed)) return StopReason::cancelled;
  if (evaluations_ >= max_evaluations_) return StopReason::evaluation_budget_spent;
  if (substeps_ >= max_substeps_) return StopReason::work_budget_spent;
  return StopReason::none;
}

PassResult Budget::pass(std::span<const WindowSample> w, const ParamVector& p, PassSettings ps) {
  ps.cancel = cancel_;
  ps.input_delay = input_delay_;
  const double span = w.back().t - w.front().t;
  const double max_pole = kMaxPolePerSample / mean_interval_;
  ps.max_substeps = static_cast<long>(std::ceil(max_pole * span / kMaxStiffnessPerSubstep)) +
                    2 * static_cast<long>(w.size());
  ++evaluations_;
  PassResult r = residual_pass(w, p, ps);
  substeps_ += r.substeps;
  return r;
}

}  // namespace scp::refine

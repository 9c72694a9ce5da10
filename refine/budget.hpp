#pragma once
// Every pass of one fit goes through a Budget: it counts the passes and the model's sub-steps
// against FitSettings' bounds, polls the cancel flag, and stops a pass whose model is stiffer
// than the window's sampling can show (kMaxPolePerSample).

#include <atomic>
#include <span>

#include "refine/fit.hpp"
#include "refine/residual_pass.hpp"
#include "refine/stop_reason.hpp"

namespace scp::refine {

// How stiff a model the fit simulates at all: ρ(A)·Δt ≤ 50 over the mean sample interval Δt. A
// mode that decays by e⁻⁵⁰ within one sample interval leaves nothing above rounding in the next
// sample, so beyond it the samples cannot tell one θ from another along the common scale of
// θ1..θ4 (the inertia) and the cost is flat there. Without this bound Levenberg–Marquardt
// follows that valley toward m → 0, and since substeps() cuts every interval into τ·ρ/1.5
// sub-steps, each pass grows slower with the stiffness without end
// (tests/refine/test_robust.cpp, AnUnidentifiableScaleEndsWithinTheBudget).
inline constexpr double kMaxPolePerSample = 50.0;

// A fast pole this far beyond the sampling (e⁻²⁰ ≈ 2e-9 of the mode left after one interval, below
// any noise) is not resolved by the window: the samples do not determine the common scale of
// θ1..θ4 there (refine/fit.cpp's verdict).
inline constexpr double kUnresolvedPolePerSample = 20.0;

class Budget {
 public:
  Budget(std::span<const WindowSample> window, const FitSettings& settings);

  // Why the fit must stop now (cancelled, a budget spent, end()), or StopReason::none.
  StopReason stop() const;
  // Every stop() from here on says `reason`.
  void end(StopReason reason) { ended_ = reason; }
  // A new start within the same fit (refine/fit.cpp's start shapes): what was spent still
  // counts, the earlier path's end does not.
  void restart_path() { ended_ = StopReason::none; }

  // Whether the mechanical block of p has, somewhere in T̄ ∈ [tbar_lo, tbar_hi], a pole beyond
  // kUnresolvedPolePerSample of the window's sampling.
  bool unresolved(const ParamVector& p, double tbar_lo, double tbar_hi) const;

  // residual_pass over `w` with the fit's cancel flag, input delay and sub-step bound, counted.
  PassResult pass(std::span<const WindowSample> w, const ParamVector& p, PassSettings ps);

  // Every pass from here on switches the voltage this much later than recorded.
  void set_input_delay(double d) { input_delay_ = d; }
  double input_delay() const { return input_delay_; }
  double mean_interval() const { return mean_interval_; }
  int evaluations() const { return evaluations_; }

 private:
  int max_evaluations_;
  long max_substeps_;
  const std::atomic<bool>* cancel_;
  double mean_interval_ = 1.0;
  int evaluations_ = 0;
  long substeps_ = 0;
  double input_delay_ = 0.0;
  StopReason ended_ = StopReason::none;
};

}  // namespace scp::refine

#pragma once
// What the stages of refine/fit.cpp share: the context every stage reads (FitContext) and the fit
// so far, which each stage takes from the one before and hands on (FitState).

#include <algorithm>
#include <array>
#include <span>

#include "refine/budget.hpp"
#include "refine/fit.hpp"
#include "refine/parameters.hpp"
#include "refine/stage.hpp"

namespace scp::refine {

struct FitContext {
  FitContext(std::span<const WindowSample> w, const FitSettings& s)
      : window(w),
        settings(s),
        max_iterations(std::max(1, s.max_iterations)),
        variance_floor{refine::variance_floor(w, 0), refine::variance_floor(w, 1)},
        budget(w, s) {}

  std::span<const WindowSample> window;
  // The caller's settings, but for a sensor's lag the window cannot determine, which the fit then
  // holds (hold_undetermined_lag).
  FitSettings settings;
  int max_iterations;                    // of each Levenberg–Marquardt run
  std::array<double, 2> variance_floor;  // x, T̄
  Budget budget;                         // every pass of the fit counts against it
};

// The noise model's variances: each channel's sensor noise, and with
// FitSettings::sample_timing_jitter the samples' timing error's (s², PassSettings).
struct NoiseVariances {
  double x = 1.0, tbar = 1.0, timing = 0.0;
  bool timing_estimated = false;  // the robust weights wait for it
};

// The voltage's delay d (FitSettings::max_input_delay_s), from T̄ alone (refine/input_delay.hpp).
struct InputDelayEstimate {
  bool ok = false;                      // estimated, with a σ
  double delay = 0.0;                   // s
  double sigma = 0.0;                   // s, after the batch-means check
  double sigma_inflation = 1.0;         // what the check scaled σ_d by
  bool at_limit = false;                // at the search's end: the timing is off by more
  ParamVector p = ParamVector::Zero();  // the thermal fit at `delay`
};

struct FitState {
  ParamVector p = ParamVector::Zero();
  int iterations = 0;  // solver iterations and search evaluations, all stages together
  NoiseVariances noise;
  TbarRange range;                     // the model's T̄ over the window, from the thermal stage
  InputDelayEstimate delay;            // set once estimated (ok)
  PassResult thermal;                  // the thermal stage's last pass (at p, lag free or held)
  bool sensor_lag_held = false;        // the lag is estimated by FitSettings but held here
  StageResult joint;                   // the joint stage's last run
  double sample_timing_sigma_s = 0.0;  // set once the joint stage has run its rounds
};

}  // namespace scp::refine

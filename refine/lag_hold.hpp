#pragma once
// A sensor's lag (NuisanceSettings::sensor_lag) that FitSettings estimates, held at its prior
// where the window cannot determine it (refine/lag_hold.cpp says why a short window cannot).

#include "refine/fit_state.hpp"
#include "refine/stage.hpp"

namespace scp::refine {

// The window separates the lag from the thermal block's other terms when its σ with them
// estimated beside it is at most this many times its σ were they known (a variance inflation of
// 4: its correlation with the best combination of them at most 0.87).
inline constexpr double kLagConfounding = 2.0;
// ... or, confounded as it may be, when it differs from its held value by more than this many σ.
inline constexpr double kLagSignificance = 3.0;

struct LagJudgement {
  bool determined = true;  // also where there is nothing to judge (the lag not among c's slots)
  double estimate = 0.0;   // s: one Gauss–Newton step from c.base (the solution, at a solution)
  double sigma = 0.0;      // s, with the other slots of c estimated beside it
  double inflation = 1.0;  // that σ over the lag's σ were the others known
};

// From a thermal pass (PassSettings weights {0, 1}) at c.base over c's slots, with T̄'s noise
// variance: whether the window determines the lag, against the value it would be held at.
LagJudgement judge_sensor_lag(const Coordinates& c, const PassResult& pass, double tbar_variance,
                              double held);

// Holds the lag at `value` for the rest of this fit (ctx.settings, state.p, sensor_lag_held).
void hold_sensor_lag(FitContext& ctx, FitState& state, double value);

// The warm refit of a fit that held the lag: one thermal pass at state.p with the lag free at
// `held` judges whether the window, which has grown since, now determines it; if not it stays
// held at `held`.
StopReason judge_held_lag(FitContext& ctx, FitState& state, double held);

}  // namespace scp::refine

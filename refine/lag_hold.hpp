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
// ... or, confounded as it may be, when it differs from its held value by more than this many σ
// (and, beside an estimated delay, by more than the delay's range on top).
inline constexpr double kLagSignificance = 3.0;

// The voltage's delay d as one more coordinate beside the thermal block's, where the fit
// estimates it (FitSettings::max_input_delay_s): to first order a lag and a delay move T̄'s
// reading alike (−τs·dT̄/dt, −d·dT̄/dt), and T̄ tells them apart only where the lag rounds T̄'s
// corners, so a lag beside a delay is judged with the delay estimated too.
struct DelayCoordinate {
  bool present = false;
  ParamVector cross = ParamVector::Zero();  // JᵀW J_d per slot of p
  double information = 0.0;                 // J_dᵀW J_d
  double score = 0.0;                       // J_dᵀW r
  double range = 0.0;                       // s, the delay's search limit
};

struct LagJudgement {
  bool determined = true;  // also where there is nothing to judge (the lag not among c's slots)
  double estimate = 0.0;   // s: one Gauss–Newton step from c.base (the solution, at a solution)
  double sigma = 0.0;      // s, with the other slots of c estimated beside it
  double inflation = 1.0;  // that σ over the lag's σ were the others known
};

// From a thermal pass (PassSettings weights {0, 1}) at c.base over c's slots, with T̄'s noise
// variance: whether the window determines the lag, against the value it would be held at; with
// `delay` present, the delay estimated beside c's slots.
LagJudgement judge_sensor_lag(const Coordinates& c, const PassResult& pass, double tbar_variance,
                              double held, const DelayCoordinate& delay = {});

// What a judgement at p needs: a thermal pass and, where the fit estimates the delay and the
// switches have room to move, the delay's column from passes at d ± h about the budget's delay
// (their centre then is the pass). `at_p` is the thermal pass at p with the budget's delay, when
// the caller has it (no pass is repeated); `stop` says cancelled.
struct LagEvidence {
  PassResult pass;
  DelayCoordinate delay;
  StopReason stop = StopReason::none;
};
LagEvidence lag_evidence(FitContext& ctx, const ParamVector& p, const PassResult* at_p);

// Holds the lag at `value` for the rest of this fit (ctx.settings, state.p, sensor_lag_held).
void hold_sensor_lag(FitContext& ctx, FitState& state, double value);

// The warm refit of a fit that held the lag: one thermal pass at state.p with the lag free at
// `held` judges whether the window, which has grown since, now determines it; if not it stays
// held at `held`.
StopReason judge_held_lag(FitContext& ctx, FitState& state, double held);

}  // namespace scp::refine

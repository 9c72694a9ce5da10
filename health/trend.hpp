#pragma once
// Per-parameter trends over a run of refined windows, and the reference they extrapolate.
//
// θ_i(t) = a_i + s_i·(t − t̄) is fitted to the windows' θ̂ at their midpoints (a window's fit of a
// linearly drifting θ is θ at its midpoint), each weighted by 1/C_ii. Windows refitted every
// 10 s over 300 s share most of their data, so their errors are far from independent: the
// covariance of two windows A and B that overlap by |A∩B| is, for information that accrues
// uniformly in time (C_A = Q/|A|),
//
//   Cov(θ̂_A, θ̂_B) = |A∩B|·Q/(|A||B|) ≈ ½|A∩B|·(C_A/|B| + C_B/|A|),
//
// and σ of the slope and of the prediction are the sandwich Σ_AB w_A w_B Cov(θ̂_A, θ̂_B) of the
// least-squares weights (treating the windows as independent would make σ(slope) about
// √(L/Δ) ≈ 5.5 times too small).

#include <span>

#include "health/types.hpp"

namespace scp::health {

Matrix6 window_cross_covariance(const WindowEstimate& a, const WindowEstimate& b) noexcept;

struct TrendFit {
  bool valid = false;       // at least one window
  bool with_slope = false;  // a slope was fitted (else the level alone)
  int windows = 0;
  double t_eval = 0.0;              // s, where `level` is
  Vector6 level = Vector6::Zero();  // θ at t_eval
  Matrix6 level_covariance = Matrix6::Zero();
  Vector6 slope = Vector6::Zero();  // per second
  Vector6 slope_sigma = Vector6::Zero();
  double data_span = 0.0;  // s, the first window's start to the last one's end
};

// The windows in time order. with_slope = false fits the level alone; a slope needs two windows
// with different midpoints. A parameter with zero variance in any window is taken as known: its
// level is the last window's θ, with no variance and no slope.
TrendFit fit_trend(std::span<const WindowEstimate> windows, double t_eval, bool with_slope);

}  // namespace scp::health

#pragma once
// An interval the window could not tell (IntervalEvidence, refine/fit.cpp's compare_intervals):
// how far θ moves between the fits under `before` and `after`, and that spread as a share of the
// covariance (the two intervals weighed with Schwarz's weights).

#include <array>

#include "refine/fit.hpp"

namespace scp::refine {

// The largest |θ_i(a) − θ_i(b)| / σ_i(a) over the free θ1..θ4; +∞ where a σ is not usable.
double mechanical_shift_sigma(const FitResult& a, const FitResult& b,
                              const std::array<bool, 6>& known);

// w·ddᵀ with d = θ(b) − θ(a) over the free θ and w = 1/(1 + e^{s/2}) the weight of b, whose
// Schwarz criterion exceeds a's by s (`statistic`, twice the log-likelihood ratio): the expected
// (θ − θ(a))(θ − θ(a))ᵀ beyond a's own covariance, θ being b's with probability w. a's θ is the one
// published, so model averaging's w(1 − w)·ddᵀ, the spread about the weighted mean, would leave
// out the (w·d)² by which that mean and a's θ differ.
Matrix6 interval_covariance(const FitResult& a, const FitResult& b, double statistic,
                            const std::array<bool, 6>& known);

// `r`'s covariance and σ with `share` added, and `share` kept as r.interval_covariance.
void add_interval_covariance(FitResult& r, const Matrix6& share);

// `r`'s covariance and σ with `share` added: what another unknown estimated beside θ adds.
void add_covariance_share(FitResult& r, const Matrix6& share);

}  // namespace scp::refine

#pragma once
// ẋ from x without lag: the three-point derivative at the middle sample, x_{k-1}, from x_{k-2},
// x_{k-1}, x_k (exact for parabolas, O(h²) error, any spacing). The price is one sample of delay,
// which the loop pays for every signal alike: it feeds the estimator sample k−1 (x, T, V and
// this ẋ) at cycle k, so the regressor stays consistent. A causal filtered differentiator instead
// lags ẋ by τ = 2ζ/ωc, which the estimator sees as an added mass bτ and which biases θ1..θ4 by the
// factor 1/(1 + θ1τ) (docs/velocity.md). Noise gain: σẋ ≈ σx/(√2·h) before the estimator's own
// β/(s+β) filtering.

#include <cmath>

#include "drivers/sample.hpp"

namespace scp::daemon::velocity {

class CentralDifference {
 public:
  // Pushes the newest sample; when two earlier ones are known, writes the middle sample with its
  // ẋ into `delayed` and returns true. Non-finite x or t restarts the history.
  bool push(const drivers::Sample& newest, drivers::Sample& delayed) noexcept {
    if (!std::isfinite(newest.x) || !std::isfinite(newest.t)) {
      count_ = 0;
      return false;
    }
    if (count_ > 0 && !(newest.t > s2_.t)) return false;  // time must advance
    s0_ = s1_;
    s1_ = s2_;
    s2_ = newest;
    if (count_ < 3) ++count_;
    if (count_ < 3) return false;
    const double h1 = s1_.t - s0_.t;
    const double h2 = s2_.t - s1_.t;
    delayed = s1_;
    delayed.xdot = -h2 / (h1 * (h1 + h2)) * s0_.x + (h2 - h1) / (h1 * h2) * s1_.x +
                   h1 / (h2 * (h1 + h2)) * s2_.x;
    return true;
  }

  void reset() noexcept { count_ = 0; }

 private:
  drivers::Sample s0_{}, s1_{}, s2_{};  // samples k−2, k−1, k
  int count_ = 0;
};

}  // namespace scp::daemon::velocity

#pragma once
// The voltage's delay d has no derivative in the pass (it moves where the switches land), so its
// derivatives are central differences of three passes at d − h, d, d + h with everything else
// the same. With C = Σ w r² and g = JᵀW r (PassResult::cost, jtwr; or one batch's share of them):
//   d's score        J_dᵀW r  = −(C(d+h) − C(d−h)) / 4h          (C' = −2 J_dᵀW r)
//   d's information  J_dᵀW J_d = (C(d+h) + C(d−h) − 2 C(d)) / 2h²  (C'' ≈ 2 J_dᵀW J_d)
//   its cross terms  JᵀW J_d  = −(g(d+h) − g(d−h)) / 2h           (∂g/∂d = −JᵀW J_d)

#include "refine/parameters.hpp"

namespace scp::refine {

struct DelayDifferences {
  double score = 0.0;
  double information = 0.0;
  ParamVector cross = ParamVector::Zero();
};

inline DelayDifferences delay_differences(double cost_below, double cost_at, double cost_above,
                                          const ParamVector& score_below,
                                          const ParamVector& score_above, double h) {
  return {.score = -(cost_above - cost_below) / (4.0 * h),
          .information = (cost_above + cost_below - 2.0 * cost_at) / (2.0 * h * h),
          .cross = -(score_above - score_below) / (2.0 * h)};
}

}  // namespace scp::refine

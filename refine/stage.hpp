#pragma once
// One stage of the staged fit (refine/fit.cpp): Levenberg–Marquardt
// (refine/levenberg_marquardt.hpp) over some of p's slots, the others held, every pass counted by
// the fit's Budget; and what the stages share about which models they accept.

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cstddef>
#include <functional>
#include <memory>
#include <span>
#include <vector>

#include "refine/budget.hpp"
#include "refine/levenberg_marquardt.hpp"
#include "refine/parameters.hpp"
#include "refine/residual_pass.hpp"

namespace scp::refine {

// The range of the model's T̄ over the window. A search on a prefix of the window takes the
// thermal stage's range over all of it, so that it does not accept a damping that turns negative
// later in the window.
struct TbarRange {
  double lo = 0.0, hi = 0.0;
};

// `range` widened by what a pass's model reached.
inline TbarRange widened(const TbarRange& range, const PassResult& pass) {
  return {std::min(pass.tbar_min, range.lo), std::max(pass.tbar_max, range.hi)};
}

// θ1 + θ2·T̄ > 0 at both ends of `range`: the mechanical block is damped everywhere in it.
inline bool damped_over(const ParamVector& p, const TbarRange& range) {
  return p[kDamping] + p[kDampingSlope] * range.lo > 0.0 &&
         p[kDamping] + p[kDampingSlope] * range.hi > 0.0;
}

// The extensions keep the stiffness θ3·(1 − κT̄), the cooling θ5·(1 + γT̄) and the resistance
// 1 + ρT̄ positive at both ends of `range` (each is linear in T̄).
inline bool extensions_physical_over(const ParamVector& p, const TbarRange& range) {
  for (const double t : {range.lo, range.hi}) {
    if (!(1.0 - p[kStiffnessSofteningSlot] * t > 0.0) || !(1.0 + p[kCoolingTempcoSlot] * t > 0.0) ||
        !(1.0 + p[kResistanceTempcoSlot] * t > 0.0))
      return false;
  }
  return true;
}

// A model the fit can simulate and accept: damped over `range`, θ3 > 0 and θ5 > 0, and the
// extensions physical over it.
inline bool stable_over(const ParamVector& p, const TbarRange& range) {
  if (!(p[kCooling] > 0.0) || !(p[kStiffness] > 0.0)) return false;
  return damped_over(p, range) && extensions_physical_over(p, range);
}

// The coordinates z a stage fits: p[index[i]] = z[i] for the slots `free` marks (in slot order),
// the others at `base`.
struct Coordinates {
  Coordinates(const FreeMask& free, const ParamVector& base);

  Eigen::Index size() const { return static_cast<Eigen::Index>(index.size()); }
  Eigen::VectorXd start() const;
  ParamVector to_p(const Eigen::VectorXd& z) const;
  Eigen::MatrixXd jacobian() const;  // ∂p/∂z (kParams × size)

  std::vector<int> index;
  ParamVector base;
};

// What a stage's trial passes (each pass but its first, at the point a step reaches) also carry:
// the covariance's sums and the model validation at the trial's θ (refine/stages.hpp,
// estimate_covariance). A stage that starts beside its solution (the warm refit) ends on such a
// pass, which then serves as the covariance's too instead of one more pass.
struct TrialCovariance {
  int hac_bandwidth = 0;
  int batches = 0;
  // A fresh validator for a trial at p (θ and the nuisance terms).
  std::function<std::shared_ptr<ResidualValidator>(const ParamVector& p)> validator;
  // The sums serve the covariance only where the solution's residuals choose hac_bandwidth's lags
  // too (a refit after its samples changed, whose start's lags were another model's); otherwise
  // at hac_bandwidth's whatever they choose (a warm refit: the slid window's lags, one or two off).
  // Where the start's residuals already choose others (a refit after the voltage's switches were
  // placed, whose start's lags came from residuals the misplaced switches coloured), no trial
  // carries them: each would be a dearer pass whose sums no one reads.
  bool only_at_own_lags = false;
  // The Newey–West lags a pass's residuals choose (estimate_covariance's rule).
  std::function<int(const PassResult&)> lags_of;

  // Whether `pass`'s residuals choose the lags these sums are taken at.
  bool chooses_own_lags(const PassResult& pass) const {
    return lags_of && lags_of(pass) + 1 == hac_bandwidth;
  }
  // Whether the trials of a stage that starts at `start` carry the sums (only_at_own_lags).
  bool serves_trials_from(const PassResult& start) const {
    return !only_at_own_lags || !start.finite || chooses_own_lags(start);
  }
};

// How a stage runs its Levenberg–Marquardt (LmSettings's members of the same names).
struct StageOptions {
  double initial_damping = kInitialDamping;
  double decrement_tolerance = kDecrementTolerance;
  const TrialCovariance* trial_covariance = nullptr;
  // > 0 (with trial_covariance): the one-step rule (LmSettings::one_step_tolerance), the start's
  // pass then also carrying the covariance's sums.
  double one_step_tolerance = 0.0;
  // Non-null (without the one-step rule): the pass at the stage's start, already at hand (the
  // joint stage's previous round at the new noise weights, refine/residual_pass.hpp's
  // reweighted()), which the first evaluation takes instead of simulating.
  const PassResult* start_pass = nullptr;
};

struct StageResult {
  ParamVector p = ParamVector::Zero();
  PassResult pass;  // at p
  // Non-null: `pass` is a trial pass that carried the covariance's sums (StageOptions), and this
  // validator saw its residuals.
  std::shared_ptr<ResidualValidator> validator;
  int iterations = 0;
  bool converged = false;
  const char* message = "";  // the solver's
  bool stopped = false;      // the budget ran out or the fit was cancelled: the fit ends here
};

// Levenberg–Marquardt from c.base over c's slots, with passes of `pass_settings` on `window`. A
// trial whose model is not finite or not stable over `range` (widened by its own pass) is a
// failed step.
StageResult run_stage(std::span<const WindowSample> window, const Coordinates& c,
                      const PassSettings& pass_settings, int max_iterations, Budget& budget,
                      const TbarRange& range = {}, const StageOptions& options = {});

// Degrees of freedom left in a channel of n samples with p parameters acting on it.
inline double dof(std::size_t n, std::size_t p) {
  return std::max(1.0, static_cast<double>(n) - static_cast<double>(p));
}

// The free slots acting on x and on T̄ (the degrees of freedom each channel's residuals lost).
std::array<std::size_t, 2> parameters_per_channel(const FreeMask& free);

// The floor of a channel's (0 x, 1 T̄) noise variance: a noise-free record must not give
// infinite weights.
double variance_floor(std::span<const WindowSample> window, int channel);

}  // namespace scp::refine

#pragma once
// The Kalman filter that PassSettings::landing_jitter runs beside the simulation, on all three
// states [x, ẋ, T̄].
//
// A voltage that landed δ off its stamp puts θ6·ΔV²·δ into T̄ that the model does not have: process
// noise on the thermal state. T̄'s error then drives x through −(θ2·ẋ + θ4)·T̄ and stays there for
// the slow mechanical pole (0.7 s for the paper's actuator), long after T̄'s own innovation has
// taken it out of T̄. A filter on T̄ alone leaves that error in x, where it is slow and correlated
// across seconds (on the simulated link it held the jitter estimate low). Carrying the 3×3
// covariance lets each T̄ innovation correct x and ẋ by the share of their error that T̄'s error
// explains (the cross-covariance), and tells the fit how uncertain x's prediction still is (P_xx,
// P_xT̄ in the residuals' covariance). Where the landings' jitter is 0 (a local DAQ, the simulated
// SCP) P stays 0 and the fit is the plain output-error one.
//
// Only T̄'s measurement updates the filter: x stays an output-error channel. Updating with x as
// well (a full prediction-error filter) whitened the residuals on the simulated link but left
// θ1..θ4 three times further off and at several σ, likely x's noise-free samples pulling the
// state onto each sample's stamp error (docs/numerics.md, "x filtered as well").

#include <Eigen/Core>

#include "refine/model_simulator.hpp"

namespace scp::refine {

// The filter's measurement update applied to a state: [x, ẋ, T̄] += K·e, e T̄'s innovation.
inline void correct_with_tbar(ModelState& s, const Eigen::Vector3d& gain,
                              double innovation) noexcept {
  s.x += gain[0] * innovation;
  s.xdot += gain[1] * innovation;
  s.tbar += gain[2] * innovation;
}

class LandingFilter {
 public:
  // Propagates the error covariance over an interval of length h, linearized at the mean of the
  // model's states at its ends, `at_start` and `at_end` (the matrix then frozen: exact for the
  // frozen system whatever h, so a gap in the record is one step). A voltage that switched inside
  // the interval, `since_landing` before its end (≤ 0: none), by `landing_step` in θ6·V², with
  // its instant's error of variance `timing_variance`, then adds the error it started in T̄
  // carried to the interval's end: by then ẋ has followed it already (the fast pole, 1 ms for the
  // paper's actuator) and x has begun to.
  void predict(const Vector6& theta, const ModelState& at_start, const ModelState& at_end, double h,
               double since_landing, double landing_step, double timing_variance) noexcept;
  // The covariance of the predicted x and T̄'s errors, [[P_xx, P_xT̄], [P_xT̄, P_T̄T̄]]: the state's
  // share of the residuals' covariance at this sample.
  Eigen::Matrix2d output_covariance() const noexcept;

  // The update with T̄'s measurement of variance `measurement_variance` (the sensor's and the
  // stamp's), counted with the robust weight `omega` (≤ 1: a down-weighted sample corrects as much
  // less as it counts). Returns the gains K = ω·P e₃/(P_T̄T̄ + R) for [x, ẋ, T̄] on T̄'s innovation.
  Eigen::Vector3d update_with_tbar(double measurement_variance, double omega) noexcept;
  const Eigen::Matrix3d& covariance() const noexcept { return p_; }

 private:
  Eigen::Matrix3d p_ = Eigen::Matrix3d::Zero();  // T̄0, x0, ẋ0 are parameters: no error at start
  bool zero_ = true;                             // P = 0 exactly: nothing to propagate
};

}  // namespace scp::refine

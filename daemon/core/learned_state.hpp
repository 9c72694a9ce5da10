#pragma once
// What the estimator learned, as plain arrays: the loop publishes it (EstimatorStateView) and the
// service's checkpoint file stores it (service/state/checkpoint.hpp), one layout for both.

#include <array>

namespace scp::daemon {

// θ̂, its information and the residuals' scale: what a restart must not lose.
struct LearnedState {
  std::array<double, 6> theta_hat{};
  std::array<double, 16> info_mech{};  // 4x4 row-major information matrix R = P⁻¹, mechanical block
  std::array<double, 4> info_thermal{};  // 2x2 row-major, thermal block
  std::array<double, 2> eps2_mean{};     // running mean of ε² per block (mechanical, thermal)
  double t = 0.0;                        // s, loop time of the state
};

}  // namespace scp::daemon

#pragma once
// The estimator's learned state as plain data: what the loop publishes for the checkpointer
// (through a Seqlock, which needs a trivially copyable type). The service writes it to a
// checkpoint file (daemon/service/checkpoints.hpp).

#include <array>

#include "estimator/estimator.hpp"

namespace scp::daemon {

struct EstimatorStateView {
  std::array<double, 6> theta_hat{};
  std::array<double, 16> info_mech{};    // row-major 4×4
  std::array<double, 4> info_thermal{};  // row-major 2×2
  std::array<double, 2> eps2_mean{};
  double t = 0.0;
  bool valid = false;  // false until the loop has published once
};

EstimatorStateView to_view(const estimator::State& state) noexcept;
estimator::State to_state(const EstimatorStateView& view) noexcept;

}  // namespace scp::daemon

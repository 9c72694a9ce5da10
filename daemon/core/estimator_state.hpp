#pragma once
// The estimator's learned state as plain data: what the loop publishes for the checkpointer
// (through a Seqlock, which needs a trivially copyable type). The service writes it to a
// checkpoint file (daemon/service/checkpoints.hpp).

#include <array>

#include "daemon/core/learned_state.hpp"
#include "estimator/estimator.hpp"

namespace scp::daemon {

struct EstimatorStateView : LearnedState {
  bool valid = false;  // false until the loop has published once
};

EstimatorStateView to_view(const estimator::State& state) noexcept;
estimator::State to_state(const EstimatorStateView& view) noexcept;

}  // namespace scp::daemon

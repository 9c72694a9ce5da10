#pragma once
// Validation of EstimatorConfig, separate from the Estimator so a daemon can check a config
// before it builds anything.

#include "estimator/estimator.hpp"

namespace scp::estimator {

// Throws std::invalid_argument whose message names the field, the bad value and the allowed
// range, e.g. "estimator config: forgetting = -1 is out of range; allowed (0, 1000] 1/s".
void validate_config(const EstimatorConfig& config);

}  // namespace scp::estimator

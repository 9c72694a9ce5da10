#pragma once
// The baseline: a converged refined window saved as "the healthy actuator" (θ̂, its covariance,
// the loop times of the window, the fit's validation verdict) with the actuator's identity, as
// JSON (docs/health.md, "Baseline file"). Pure: text in, text out; the service does the I/O.

#include <cstdint>
#include <optional>
#include <string>

#include "health/types.hpp"

namespace scp::daemon::health {

struct Baseline {
  scp::health::WindowEstimate window;
  std::string actuator;  // actuator.name it was saved for
  std::string driver;
  std::string verdict;  // the refined fit's validation verdict; "untested" when it had none
  std::int64_t saved_unix_ns = 0;
};

std::string to_json(const Baseline& baseline);
// nullopt with `error` naming the field when the text is not a baseline (not JSON, wrong format,
// missing or non-finite fields, a covariance that is not symmetric with a non-negative diagonal).
std::optional<Baseline> parse_baseline(const std::string& text, std::string& error);

}  // namespace scp::daemon::health

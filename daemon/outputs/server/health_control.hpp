#pragma once
// What the socket server asks of the actuator's health (docs/health.md): the monitor's view for
// STATUS, ESTIMATE and HEALTH, and the baseline and acknowledgement requests. The service
// implements it (daemon/service/health_service.hpp): the server does no file I/O of its own and
// never talks to the monitor's thread except through it.

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>

#include "daemon/analysis/health/health_view.hpp"

namespace scp::daemon::server {

struct HealthOutcome {
  bool ok = false;
  std::string message;  // why not, or what was done
};

class HealthControl {
 public:
  virtual ~HealthControl() = default;
  virtual health::HealthView view() const = 0;
  // Changes whenever view() does (the ESTIMATE cache's key).
  virtual std::uint64_t version() const = 0;
  // The baseline in use as its file holds it, or an object with "present": false.
  virtual nlohmann::json baseline() const = 0;
  // `now_t`: the loop time (PublishedState::uptime_s).
  virtual HealthOutcome save_baseline(double now_t) = 0;
  virtual HealthOutcome clear_baseline() = 0;
  virtual HealthOutcome acknowledge(double now_t) = 0;
};

}  // namespace scp::daemon::server

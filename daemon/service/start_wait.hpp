#pragma once
// The service's side of a device awaited at start (driver.start_timeout_s). The loop stays in
// STARTING at 0 V until the device's first fresh reading and publishes why it is not there yet;
// this class, on the service thread, logs that reason each time it changes, logs the moment the
// device answers, and says when the bound is spent so the service can exit with 69.

#include <string>

#include "daemon/core/published_state.hpp"

namespace scp::daemon {

class StartWait {
 public:
  enum class Verdict { waiting, answered, timed_out };

  // timeout_s: driver.start_timeout_s (0 = without limit); endpoint: what the messages name.
  StartWait(double timeout_s, std::string endpoint);

  // `elapsed_s`: since the device was opened. After `answered` or `timed_out` it says the same.
  Verdict observe(const PublishedState& now, double elapsed_s);

  // How long the service may sleep before the bound falls due (capped at `cap_s`).
  double sleep_s(double elapsed_s, double cap_s) const;

  // The message of the exit: the key, what was awaited, the last reason and the remedy.
  std::string timeout_message() const;

 private:
  double timeout_s_;
  std::string endpoint_;
  Verdict verdict_ = Verdict::waiting;
  std::string last_reason_;
  bool announced_ = false;
};

}  // namespace scp::daemon

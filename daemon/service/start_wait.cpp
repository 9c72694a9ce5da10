#include "daemon/service/start_wait.hpp"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstring>
#include <utility>

#include "daemon/outputs/log/journal_log.hpp"

namespace scp::daemon {

StartWait::StartWait(double timeout_s, std::string endpoint)
    : timeout_s_(timeout_s), endpoint_(std::move(endpoint)) {}

StartWait::Verdict StartWait::observe(const PublishedState& now, double elapsed_s) {
  if (verdict_ != Verdict::waiting) return verdict_;
  if (!(now.state == RunState::starting && now.awaiting_device)) {
    verdict_ = Verdict::answered;
    if (announced_) log::notice("{} answered after {:.1f} s", endpoint_, elapsed_s);
    return verdict_;
  }
  const std::string reason(now.waiting_reason.data(),
                           strnlen(now.waiting_reason.data(), now.waiting_reason.size()));
  if (!reason.empty() && reason != last_reason_) {
    // One line per new reason (the driver's reconnection attempts are logged on their own).
    spdlog::info("waiting for {} ({:.1f} s; driver.start_timeout_s {}): {}; output commanded 0 V",
                 endpoint_, elapsed_s,
                 timeout_s_ > 0.0 ? fmt::format("{} s", timeout_s_) : std::string("0, no limit"),
                 reason);
    last_reason_ = reason;
    announced_ = true;
  }
  if (timeout_s_ > 0.0 && elapsed_s >= timeout_s_) verdict_ = Verdict::timed_out;
  return verdict_;
}

double StartWait::sleep_s(double elapsed_s, double cap_s) const {
  if (verdict_ != Verdict::waiting || timeout_s_ <= 0.0) return cap_s;
  return std::clamp(timeout_s_ - elapsed_s, 0.001, cap_s);
}

std::string StartWait::timeout_message() const {
  return fmt::format(
      "{} did not answer within driver.start_timeout_s = {} s ({}); exiting with 69 "
      "(EX_UNAVAILABLE). Check that the DAQ is powered, wired and reachable, or raise "
      "driver.start_timeout_s (0 waits without limit)",
      endpoint_, timeout_s_, last_reason_.empty() ? "no reading arrived" : last_reason_);
}

}  // namespace scp::daemon

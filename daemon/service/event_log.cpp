#include "daemon/service/event_log.hpp"

#include <spdlog/spdlog.h>

#include <cstdio>
#include <cstring>

#include "daemon/outputs/log/journal_log.hpp"
#include "daemon/outputs/server/render.hpp"

namespace scp::daemon {
namespace {

std::string text_of(const std::array<char, kReasonChars>& text) {
  return {text.data(), strnlen(text.data(), text.size())};
}

}  // namespace

std::string output_text(const drivers::DriverStats& d) {
  char text[160];
  if (d.output_confirmed) {
    std::snprintf(text, sizeof text, "output at %.4g V", d.output_v);
  } else {
    std::snprintf(text, sizeof text,
                  "output UNCONFIRMED (0 V not acknowledged; the device last acknowledged "
                  "%.4g V)",
                  d.output_v);
  }
  return text;
}

std::optional<std::string> EventLog::observe(const PublishedState& now,
                                             const drivers::Driver& driver) {
  driver_changes(now.driver, driver);
  const FaultHistory& was = last_.faults;
  const FaultHistory& is = now.faults;
  const std::uint64_t new_faults = is.count - was.count;
  // A fault now showing is logged with the output's state; one that came and went between two
  // snapshots (or more than one) with its time, so that none goes unseen.
  const bool faulted_now = now.state == RunState::fault && new_faults > 0;
  const std::uint64_t unseen = faulted_now ? new_faults - 1 : new_faults;
  if (unseen > 0) {
    spdlog::error(
        "FAULT (cleared before it could be reported; {} in this interval) at {} (loop "
        "time {:.3f} s): {}",
        unseen, server::utc_time(is.last_unix_ns), is.last_t, text_of(is.last_reason));
  }
  if (faulted_now) {
    spdlog::error("FAULT, {}: {} (fault {} since start)", output_text(now.driver),
                  text_of(now.fault_reason), is.count);
  }
  std::optional<std::string> status;
  if (now.state != last_.state) {
    const char* from = to_string(last_.state);
    const char* to = to_string(now.state);
    if (now.state == RunState::fault) {
      status = "FAULT: " + text_of(now.fault_reason);
    } else {
      std::string how;
      if (is.recoveries > was.recoveries) {
        how = " (recovered by itself: the cause was gone for safety.recover_after_s)";
      } else if (is.cleared > was.cleared) {
        how = " (fault cleared by clear-fault)";
      }
      log::notice("state {} (was {}){}", to, from, how);
      status = to;
    }
  }
  last_ = now;
  return status;
}

// Why transactions fail and links come back, from the counters the loop publishes.
void EventLog::driver_changes(const drivers::DriverStats& now, const drivers::Driver& driver) {
  const drivers::DriverStats& last = last_.driver;
  const auto failures =
      (now.read_errors + now.write_errors) - (last.read_errors + last.write_errors);
  if (failures > 0 && now.last_error != nullptr && now.last_error[0] != '\0') {
    spdlog::debug("driver: {} failed transaction(s), the latest: {}", failures, now.last_error);
  }
  if (now.late_replies > last.late_replies) {
    spdlog::debug("driver: {} late reply(ies) recognised and discarded ({} in all)",
                  now.late_replies - last.late_replies, now.late_replies);
  }
  if (now.link_up != last.link_up) {
    if (now.link_up) {
      log::notice("driver: link up again (reconnection {}), 0 V written first", now.reconnects);
    } else {
      spdlog::warn(
          "driver: link down ({}); reconnecting in the background",
          now.last_error != nullptr && now.last_error[0] != '\0' ? now.last_error : "no reply");
    }
  }
  if (!now.link_up) {
    const std::string why = driver.background_error();
    if (!why.empty() && why != last_reconnect_error_) spdlog::info("driver: reconnection {}", why);
    last_reconnect_error_ = why;
  }
}

}  // namespace scp::daemon

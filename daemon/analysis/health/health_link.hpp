#pragma once
// Between the thread that runs the health monitor (the refinement's worker) and the others: the
// view it publishes through a Seqlock, and the commands the socket server hands it (a new or no
// baseline, an acknowledgement) through a mailbox. Neither thread is the loop: the mailbox's
// mutex is held only to move a vector, never while a fit or a request runs.

#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "daemon/analysis/health/baseline.hpp"
#include "daemon/analysis/health/health_runner.hpp"
#include "daemon/analysis/health/health_view.hpp"
#include "daemon/core/rt/seqlock.hpp"

namespace scp::daemon::health {

struct HealthCommand {
  enum class Kind { baseline, acknowledge };
  Kind kind = Kind::acknowledge;
  std::optional<Baseline> baseline;  // Kind::baseline: nullopt clears it
  std::string source;                // where the baseline is kept
  double t = 0.0;                    // Kind::acknowledge: loop time
};

class HealthLink {
 public:
  void post(HealthCommand command) {
    const std::lock_guard<std::mutex> lock(mutex_);
    pending_.push_back(std::move(command));
  }
  std::vector<HealthCommand> take() {
    std::vector<HealthCommand> out;
    const std::lock_guard<std::mutex> lock(mutex_);
    out.swap(pending_);
    return out;
  }
  rt::Seqlock<HealthView>& view() noexcept { return view_; }
  const rt::Seqlock<HealthView>& view() const noexcept { return view_; }

 private:
  std::mutex mutex_;
  std::vector<HealthCommand> pending_;
  rt::Seqlock<HealthView> view_;
};

// Carries out the commands posted since the last call, then returns the monitor's events.
std::vector<scp::health::HealthEvent> apply_commands(HealthRunner& runner, HealthLink& link);

// One journal line at warning per event (notice for an acknowledgement).
void log_event(const scp::health::HealthEvent& event);
// "changed at 612.0 s (onset 605.3 s, fast): 1/(R Cth) -9.2 % (σ 0.8 %)"
std::string describe(const scp::health::HealthEvent& event);

}  // namespace scp::daemon::health

#pragma once
// The thread that runs the refinement in the service: ordinary scheduling (SCHED_BATCH at the
// process's nice), below the real-time loop, which it never makes wait. It drains the loop's
// hand-off ring into the Refiner, fits every refine.interval_s, reads the paper law's θ̂ and σ from
// the loop's published state at each fit and publishes a RefinedView through its own Seqlock.

#include <atomic>
#include <memory>
#include <thread>

#include "daemon/analysis/refine/refined_view.hpp"
#include "daemon/analysis/refine/refiner.hpp"
#include "daemon/config/daemon_config.hpp"
#include "daemon/core/handoff.hpp"
#include "daemon/core/published_state.hpp"
#include "daemon/core/rt/seqlock.hpp"

namespace scp::daemon::refine {

// Loop time, wall clock and the paper law's estimate: what a fit needs from the published state.
PaperEstimate paper_estimate(const PublishedState& state) noexcept;

class RefineWorker {
 public:
  // Everything referenced must outlive the worker. Allocates the window here, before the loop
  // starts.
  // `observer` (may be null) sees every sample and fit, and is polled after every drain.
  RefineWorker(const config::DaemonConfig& config, HandOffRing& ring,
               const rt::Seqlock<PublishedState>& published, rt::Seqlock<RefinedView>& out,
               FitObserver* observer = nullptr);
  ~RefineWorker();  // stop()s
  RefineWorker(const RefineWorker&) = delete;
  RefineWorker& operator=(const RefineWorker&) = delete;

  void start();
  // Idempotent. A fit in progress is cancelled (it polls the stop flag about every millisecond
  // of simulation) and its result is not published.
  void stop() noexcept;

 private:
  void run() noexcept;
  // Says once in the journal that the voltage's interval is undetermined, and the remedy.
  void note_interval(const RefinedView& view);

  HandOffRing& ring_;
  const rt::Seqlock<PublishedState>& published_;
  rt::Seqlock<RefinedView>& out_;
  Refiner refiner_;
  FitObserver* observer_;
  std::atomic<bool> stop_{false};
  bool interval_noted_ = false;  // note_interval has said it
  std::thread thread_;
};

}  // namespace scp::daemon::refine

#include "daemon/analysis/refine/refine_worker.hpp"

#include <pthread.h>
#include <sched.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <cstring>

#include "common/clock.hpp"
#include "daemon/analysis/refine/best.hpp"

namespace scp::daemon::refine {

namespace {

// Drained this often between fits: 20 samples at 1 kHz, far from the ring's 16384.
constexpr auto kPollPeriod = std::chrono::milliseconds(20);

// Below the loop: the loop is SCHED_FIFO when the real-time set-up succeeded, which no ordinary
// thread delays whatever its nice level; SCHED_BATCH (never preempts a running thread on wake-up)
// keeps the worker off it when it did not. Not below everything else on the PC: at nice 10 a busy
// machine starved it (under `stress --cpu 2` plus a 2-job batch run on 2 cores, fits of a 20 s
// window took 21-24 s of wall time, longer than the 16 s hand-off ring holds: 4,180-7,017
// samples dropped and the window restarted at every fit, so it never grew). It now gets
// a fair share like any other user process: it keeps the process's own nice
// level (a unit's Nice= applies to it).
void lower_priority() {
  sched_param param{};
  param.sched_priority = 0;
  if (const int err = pthread_setschedparam(pthread_self(), SCHED_BATCH, &param); err != 0) {
    spdlog::warn("refinement worker: cannot use SCHED_BATCH ({}); it stays SCHED_OTHER",
                 std::strerror(err));
  }
}

}  // namespace

PaperEstimate paper_estimate(const PublishedState& state) noexcept {
  return {state.estimate.theta_hat, state.estimate.sigma};
}

RefineWorker::RefineWorker(const config::DaemonConfig& config, HandOffRing& ring,
                           const rt::Seqlock<PublishedState>& published,
                           rt::Seqlock<RefinedView>& out, FitObserver* observer)
    : ring_(ring),
      published_(published),
      out_(out),
      refiner_(config.refine, config.estimator, config.loop.period_s),
      observer_(observer) {
  refiner_.set_observer(observer);
  // stop() must not wait for a fit of a long window (or one on a hard window) to finish.
  refiner_.set_cancel(&stop_);
  out_.store(refiner_.view());
}

RefineWorker::~RefineWorker() {
  stop();
}

void RefineWorker::start() {
  thread_ = std::thread([this] { run(); });
}

void RefineWorker::stop() noexcept {
  stop_.store(true, std::memory_order_release);
  if (thread_.joinable()) thread_.join();
}

void RefineWorker::note_interval(const RefinedView& view) {
  if (interval_noted_ || !interval_in_doubt(view)) return;
  interval_noted_ = true;
  spdlog::warn("refinement: {}", interval_advice(view));
}

void RefineWorker::run() noexcept {
  try {
    lower_priority();
    while (!stop_.load(std::memory_order_acquire)) {
      refiner_.drain(ring_);
      if (observer_ != nullptr) observer_->poll();
      if (!refiner_.due()) {
        std::this_thread::sleep_for(kPollPeriod);
        continue;
      }
      const PublishedState now = published_.load();
      const RefinedView& view = refiner_.fit(paper_estimate(now), now.uptime_s, clock::unix_ns());
      if (stop_.load(std::memory_order_acquire)) break;  // cancelled: not a result
      out_.store(view);
      spdlog::debug("refinement: fit {} of [{:.1f}, {:.1f}] s ({} samples) in {:.3f} s: {} ({})",
                    view.fits, view.t_begin, view.t_end, view.samples, view.duration_s,
                    view.converged ? "converged" : "not converged", view.message.data());
      note_interval(view);
    }
  } catch (const std::exception& e) {
    // Only the solver's allocations can throw here; the loop and the paper law go on without it.
    spdlog::error("refinement worker stopped: {}", e.what());
  }
}

}  // namespace scp::daemon::refine

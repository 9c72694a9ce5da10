#pragma once
// `--offline --jobs N` (N > 1): the batch run's fits on N worker threads ("lanes") beside the
// loop, instead of inline between its cycles. Everything a fit leaves behind is applied on the
// caller's thread in the order the fits were made, as inline: the fit's view (counters summed
// over the lanes), the recorder's view, and the observer (the health monitor), which sees every
// sample and fit in the inline sequence.
//
// Each lane is a whole refine::Refiner fed every sample, and makes every N-th fit: its own
// previous fit, N fits (N × refine.interval_s) earlier, is its warm start and seed, carried along
// the samples its window drops, where inline uses the fit just before. When that warm refit does
// not converge within its iterations (the start is N intervals away), the lane waits for the fit
// just before its own and tries a warm refit from it, as inline would have, before the full fit
// (refine::fit's fallback). A fit is made at the
// cycle inline makes it, except after a fit that stalled: inline waits for the next fit (a
// doubled or renewed window, Refiner::due); here that is learnt when the stalled fit is applied,
// after the fits already under way (N - 1 at most) were made at the usual interval, and from then
// on, until a fit that does not stall, the fits are made one at a time. What a fit finds depends
// only on the samples and on the fits before it, never on which thread finishes first: the same
// file gives the same summary every run.

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <exception>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

#include "daemon/analysis/refine/refiner.hpp"
#include "daemon/config/daemon_config.hpp"
#include "daemon/core/handoff.hpp"

namespace scp::daemon {

class ParallelRefinement {
 public:
  // Called with each fit's view as it is applied (the recorder's ring).
  using Applied = std::function<void(const refine::RefinedView&)>;

  // Starts `jobs` lanes (at least 2). `observer` (may be null) must outlive this.
  ParallelRefinement(const config::DaemonConfig& cfg, unsigned jobs, refine::FitObserver* observer,
                     Applied applied);
  ~ParallelRefinement();  // joins the lanes (a fit under way finishes first)
  ParallelRefinement(const ParallelRefinement&) = delete;
  ParallelRefinement& operator=(const ParallelRefinement&) = delete;

  // Everything waiting in the loop's ring, then a fit when one is due at loop time `t` (may
  // wait for the lane that will make it to finish its previous fit).
  void after_cycle(HandOffRing& ring, double t, const refine::PaperEstimate& paper);
  // At the end of the run: the final window's fit when it holds samples no fit has seen, then
  // every fit applied.
  void finish(HandOffRing& ring, double t, const refine::PaperEstimate& paper);

  // The latest applied fit; fits, converged_fits and warm_fits count every lane's.
  const refine::RefinedView& view() const noexcept { return view_; }
  // Loop time of the oldest fit made but not yet applied: rows of a recording from then on wait
  // for its view.
  std::optional<double> first_unapplied_t() const noexcept;

 private:
  struct Lane;
  struct Made {                  // a fit made and not yet applied
    std::uint64_t samples_seen;  // observer samples due before its on_fit
    std::uint64_t window;        // the window it was made in (the shadow's count)
    double t;                    // loop time it was made at
    double t_end;                // its window's last sample
  };
  using Finished = std::shared_ptr<const scp::refine::FitResult>;
  class SampleQueue;

  void drain(HandOffRing& ring);
  bool due_by_interval() const noexcept;
  bool stall_waits() const noexcept;
  void make_fit(double t, const refine::PaperEstimate& paper);
  void apply_through(std::uint64_t fit);
  void apply_next();
  void merge_view(const Lane& lane);
  void run_lane(Lane& lane) noexcept;
  // Fit `fit` as its lane left it, once it has finished; null if it failed or the run stops.
  Finished wait_finished(std::uint64_t fit);

  config::RefineSettings settings_;
  double tolerance_s_;
  refine::FitObserver* observer_;
  Applied applied_cb_;
  std::unique_ptr<SampleQueue> observed_;  // samples the observer has not seen yet
  // Fed every sample and never fitted: the window inline would fit (its restarts, its span).
  std::unique_ptr<refine::Refiner> shadow_;
  std::vector<std::unique_ptr<Lane>> lanes_;
  std::deque<Made> made_;
  std::uint64_t dispatched_ = 0, applied_ = 0;
  std::uint64_t window_ = 0;  // the shadow's windows when the last fit was made
  bool fitted_in_window_ = false;
  double last_fit_t_end_ = 0.0;
  // The latest applied fit stalled in the current window: its last sample and the wait.
  double stalled_t_end_ = 0.0, rejected_wait_s_ = 0.0;
  double last_front_t_ = 0.0;  // the first sample of the last fit's window
  refine::RefinedView view_{};

  std::mutex mutex_;  // guards each lane's job and state, and finished_
  // Each fit's result from when it finishes until the fit after it has been applied.
  std::map<std::uint64_t, Finished> finished_;
  std::condition_variable work_, done_;
  bool stopping_ = false;
};

}  // namespace scp::daemon

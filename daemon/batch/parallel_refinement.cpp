#include "daemon/batch/parallel_refinement.hpp"

#include <algorithm>
#include <cmath>

#include "common/clock.hpp"

namespace scp::daemon {

namespace {

bool all_finite(const std::array<double, 6>& v) noexcept {
  return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
}

}  // namespace

// The samples the shadow accepted (those inline's refiner shows its observer), held until the
// fit they precede is applied.
class ParallelRefinement::SampleQueue final : public refine::FitObserver {
 public:
  void on_sample(const scp::refine::WindowSample& sample) noexcept override {
    samples_.push_back(sample);  // a batch run may allocate; std::bad_alloc ends it
    ++pushed_;
  }
  void on_fit(const scp::refine::FitResult&, std::span<const scp::refine::WindowSample>,
              std::int64_t) override {}

  std::uint64_t pushed() const noexcept { return pushed_; }
  // Shows `observer` every sample up to the `until`-th.
  void show(refine::FitObserver& observer, std::uint64_t until) noexcept {
    for (; shown_ < until && !samples_.empty(); ++shown_) {
      observer.on_sample(samples_.front());
      samples_.pop_front();
    }
  }

 private:
  std::deque<scp::refine::WindowSample> samples_;
  std::uint64_t pushed_ = 0, shown_ = 0;
};

// One worker: a refiner of its own, fed every sample, that makes every N-th fit. The caller's
// thread touches `refiner` and `fit` only while the lane is idle or done, `pending` only itself.
struct ParallelRefinement::Lane final : refine::FitObserver {
  Lane(const config::DaemonConfig& cfg) : refiner(cfg.refine, cfg.estimator, cfg.loop.period_s) {
    refiner.set_observer(this);
  }
  void on_sample(const scp::refine::WindowSample&) noexcept override {}
  // The fit and the window it read, for the caller's observer: the window stays valid while the
  // lane is done (its refiner takes no sample before its next job).
  void on_fit(const scp::refine::FitResult& result,
              std::span<const scp::refine::WindowSample> window, std::int64_t wall) override {
    fit = result;
    fit_window = window;
    wall_ns = wall;
  }

  refine::Refiner refiner;
  scp::refine::FitResult fit;
  std::span<const scp::refine::WindowSample> fit_window;
  std::int64_t wall_ns = 0;
  std::vector<HandOff> pending;  // samples since its last job (the caller's thread)
  // The job, under the mutex.
  enum class State { idle, queued, done } state = State::idle;
  std::vector<HandOff> job;
  refine::PaperEstimate paper;
  double t = 0.0;
  std::int64_t job_wall_ns = 0;
  std::exception_ptr error;
  std::thread thread;
};

ParallelRefinement::ParallelRefinement(const config::DaemonConfig& cfg, unsigned jobs,
                                       refine::FitObserver* observer, Applied applied)
    : settings_(cfg.refine),
      tolerance_s_(0.5 * cfg.loop.period_s),
      observer_(observer),
      applied_cb_(std::move(applied)),
      observed_(std::make_unique<SampleQueue>()),
      shadow_(std::make_unique<refine::Refiner>(cfg.refine, cfg.estimator, cfg.loop.period_s)) {
  shadow_->set_observer(observed_.get());
  view_.interval_s = settings_.interval_s;
  for (unsigned i = 0; i < std::max(jobs, 2U); ++i) lanes_.push_back(std::make_unique<Lane>(cfg));
  for (auto& lane : lanes_) lane->thread = std::thread([this, &l = *lane] { run_lane(l); });
}

ParallelRefinement::~ParallelRefinement() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  work_.notify_all();
  for (auto& lane : lanes_) {
    if (lane->thread.joinable()) lane->thread.join();
  }
}

void ParallelRefinement::run_lane(Lane& lane) noexcept {
  std::unique_lock lock(mutex_);
  for (;;) {
    work_.wait(lock, [&] { return stopping_ || lane.state == Lane::State::queued; });
    if (stopping_) return;
    lock.unlock();
    try {
      for (const HandOff& h : lane.job) lane.refiner.accept(h);
      lane.refiner.fit(lane.paper, lane.t, lane.job_wall_ns);
    } catch (...) {
      lane.error = std::current_exception();  // rethrown where the fit is applied
    }
    lane.job.clear();
    lock.lock();
    lane.state = Lane::State::done;
    done_.notify_all();
  }
}

void ParallelRefinement::drain(HandOffRing& ring) {
  HandOff handoff;
  while (ring.try_pop(handoff)) {
    shadow_->accept(handoff);
    for (auto& lane : lanes_) lane->pending.push_back(handoff);
  }
  // A new window (a break in the data): no fit in it yet, and no stall to wait out.
  if (shadow_->view().windows != window_) {
    window_ = shadow_->view().windows;
    fitted_in_window_ = false;
    stalled_wait_s_ = 0.0;
  }
}

// Refiner::due() without the stall: the shadow never fits, so its own due() says only whether
// its window spans refine.min_window_s.
bool ParallelRefinement::due_by_interval() const noexcept {
  if (!shadow_->due()) return false;
  if (!fitted_in_window_) return true;
  return shadow_->window().back().t - last_fit_t_end_ + tolerance_s_ >= settings_.interval_s;
}

bool ParallelRefinement::stall_waits() const noexcept {
  return stalled_wait_s_ > 0.0 &&
         shadow_->window().back().t - stalled_t_end_ + tolerance_s_ < stalled_wait_s_;
}

void ParallelRefinement::after_cycle(HandOffRing& ring, double t,
                                     const refine::PaperEstimate& paper) {
  drain(ring);
  if (!due_by_interval()) return;
  // What the fit N before this one found decides whether it waits: only that fit, so that the
  // order in which the lanes finish never matters.
  const std::uint64_t lanes = lanes_.size();
  if (dispatched_ >= lanes) apply_through(dispatched_ - lanes);
  if (stall_waits()) return;
  make_fit(t, paper);
}

void ParallelRefinement::finish(HandOffRing& ring, double t, const refine::PaperEstimate& paper) {
  drain(ring);
  const bool unfitted =
      shadow_->due() && (!fitted_in_window_ || shadow_->window().back().t > last_fit_t_end_);
  if (unfitted) {
    const std::uint64_t lanes = lanes_.size();
    if (dispatched_ >= lanes) apply_through(dispatched_ - lanes);
    make_fit(t, paper);
  }
  if (dispatched_ > 0) apply_through(dispatched_ - 1);
  if (observer_ != nullptr) observed_->show(*observer_, observed_->pushed());
}

std::optional<double> ParallelRefinement::first_unapplied_t() const noexcept {
  if (made_.empty()) return std::nullopt;
  return made_.front().t;
}

// On the lane after the one that made the previous fit; that lane has applied its own last.
void ParallelRefinement::make_fit(double t, const refine::PaperEstimate& paper) {
  Lane& lane = *lanes_[dispatched_ % lanes_.size()];
  const double t_end = shadow_->window().back().t;
  made_.push_back({observed_->pushed(), window_, t, t_end});
  {
    std::lock_guard lock(mutex_);
    lane.job.swap(lane.pending);  // the lane cleared its last job: `pending` starts empty
    lane.paper = paper;
    lane.t = t;
    lane.job_wall_ns = clock::unix_ns();
    lane.state = Lane::State::queued;
  }
  work_.notify_all();
  fitted_in_window_ = true;
  last_fit_t_end_ = t_end;
  ++dispatched_;
}

void ParallelRefinement::apply_through(std::uint64_t fit) {
  while (applied_ <= fit) apply_next();
}

// The next fit in the order made: waits for it, then what inline does after Refiner::fit.
void ParallelRefinement::apply_next() {
  Lane& lane = *lanes_[applied_ % lanes_.size()];
  {
    std::unique_lock lock(mutex_);
    done_.wait(lock, [&] { return lane.state == Lane::State::done; });
  }
  if (lane.error) std::rethrow_exception(lane.error);
  const Made made = made_.front();
  made_.pop_front();
  if (observer_ != nullptr) {
    observed_->show(*observer_, made.samples_seen);
    observer_->on_fit(lane.fit, lane.fit_window, lane.wall_ns);
  }
  merge_view(lane);
  // The stall rule of Refiner::fit, for the fits made from now on in the same window.
  const bool stalled = lane.fit.stop == scp::refine::StopReason::stalled && made.window == window_;
  stalled_t_end_ = made.t_end;
  stalled_wait_s_ = stalled ? std::min(lane.fit.t_end - lane.fit.t_begin, settings_.window_s) : 0.0;
  if (applied_cb_) applied_cb_(view_);
  {
    std::lock_guard lock(mutex_);
    lane.state = Lane::State::idle;
  }
  ++applied_;
}

// The lane's view of its fit, with the counters of every lane's fits, and the paper law's bias
// test held through the fits that do not make one, as Refiner::note_converged holds it.
void ParallelRefinement::merge_view(const Lane& lane) {
  const refine::RefinedView& latest = lane.refiner.view();
  refine::RefinedView merged = latest;
  merged.fits = applied_ + 1;
  merged.converged_fits = view_.converged_fits + (latest.converged ? 1 : 0);
  merged.warm_fits = view_.warm_fits + (latest.warm ? 1 : 0);
  const bool tested =
      latest.converged && all_finite(lane.paper.theta_hat) && all_finite(lane.paper.sigma);
  if (!tested) {
    merged.bias_tested = view_.bias_tested;
    merged.paper_biased = view_.paper_biased;
    merged.bias_statistic = view_.bias_statistic;
    merged.bias_threshold = view_.bias_threshold;
  }
  view_ = merged;
}

}  // namespace scp::daemon

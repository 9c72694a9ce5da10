#include "daemon/batch/parallel_refinement.hpp"

#include <algorithm>
#include <cmath>

#include "common/clock.hpp"
#include "refine/warm_start.hpp"

namespace scp::daemon {

namespace {

using scp::refine::FitResult;
using scp::refine::FitSettings;
using scp::refine::WarmFallback;
using scp::refine::WarmStart;
using scp::refine::WindowSample;

bool all_finite(const std::array<double, 6>& v) noexcept {
  return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
}

}  // namespace

// The samples the shadow accepted (those inline's refiner shows its observer), held until the
// fit they precede is applied.
class ParallelRefinement::SampleQueue final : public refine::FitObserver {
 public:
  void on_sample(const scp::refine::WindowSample& sample) noexcept override {
    // A batch run may allocate: the queue holds the samples that came while fits were under way.
    samples_.push_back(sample);
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
  Lane(const config::DaemonConfig& cfg, ParallelRefinement& owner_)
      : owner(owner_),
        refiner(
            cfg.refine, cfg.estimator, cfg.loop.period_s,
            [this](std::span<const WindowSample> window, const scp::refine::Vector6& start,
                   const FitSettings& settings) { return fit_window(window, start, settings); }) {
    refiner.set_observer(this);
  }
  void on_sample(const WindowSample&) noexcept override {}
  // The fit and the window it read, for the caller's observer: the window stays valid while the
  // lane is done (its refiner takes no sample before its next job).
  void on_fit(const FitResult& result, std::span<const WindowSample> window,
              std::int64_t wall) override {
    fit = result;
    fit_window_read = window;
    wall_ns = wall;
  }
  void collect_bridge();
  FitResult fit_window(std::span<const WindowSample> window, const scp::refine::Vector6& start,
                       const FitSettings& settings);
  bool neighbour_warm(std::span<const WindowSample> window, const FitSettings& settings,
                      WarmStart& warm);

  ParallelRefinement& owner;
  refine::Refiner refiner;
  FitResult fit;
  std::span<const WindowSample> fit_window_read;
  std::int64_t wall_ns = 0;
  std::vector<HandOff> pending;  // samples since its last job (the caller's thread)
  // The job, under the mutex.
  enum class State { idle, queued, done } state = State::idle;
  std::vector<HandOff> job;
  refine::PaperEstimate paper;
  double t = 0.0;
  std::int64_t job_wall_ns = 0;
  std::uint64_t index = 0;  // the fit's number in the run
  // The fit before it (index - 1, on another lane) may seed it: its window's first sample, this
  // window's, and the samples from the one to the other, which this lane's window drops.
  bool has_neighbour = false;
  double neighbour_front_t = 0.0, front_t = 0.0;
  std::vector<WindowSample> bridge;
  int calls = 0;  // refine::fit calls in this job: the second is Refiner's second start
  std::exception_ptr error;
  std::thread thread;
};

// Before the job's samples enter the window: those from the neighbour's first to this window's.
void ParallelRefinement::Lane::collect_bridge() {
  bridge.clear();
  if (!has_neighbour) return;
  const auto keep = [&](const WindowSample& s) {
    if (s.t >= neighbour_front_t && s.t <= front_t) bridge.push_back(s);
  };
  const refine::SampleWindow& window = refiner.window();
  for (std::size_t i = 0; i < window.size(); ++i) keep(window.at(i));
  for (const HandOff& h : job) keep(h.sample);
}

// refine::fit, with one more warm start before its full fit: the fit just before this one, which
// inline would have started from. The attempts' work counts in what the fit cost, as in
// refine::fit.
FitResult ParallelRefinement::Lane::fit_window(std::span<const WindowSample> window,
                                               const scp::refine::Vector6& start,
                                               const FitSettings& settings) {
  if (calls++ > 0 || !has_neighbour) return scp::refine::fit(window, start, settings);
  FitResult own;
  own.warm_fallback = WarmFallback::not_requested;
  if (settings.warm != nullptr) {
    own = scp::refine::refit(window, *settings.warm, settings);
    if (own.warm) return own;
  }
  int iterations = own.iterations, evaluations = own.evaluations;
  WarmFallback why = own.warm_fallback;  // the reason inline would give: the neighbour's, if tried
  if (WarmStart warm; neighbour_warm(window, settings, warm)) {
    FitResult r = scp::refine::refit(window, warm, settings);
    iterations += r.iterations;
    evaluations += r.evaluations;
    if (r.warm) {
      r.iterations = iterations;
      r.evaluations = evaluations;
      return r;
    }
    why = r.warm_fallback;
  }
  FitSettings cold = settings;
  cold.warm = nullptr;
  FitResult result = scp::refine::fit(window, start, cold);
  result.warm_fallback = why;
  result.iterations += iterations;
  result.evaluations += evaluations;
  return result;
}

// The warm start the fit before this one leaves at this window's first sample, as the refiner
// carries its own (refine::warm_start, then refine::shift over each sample between).
bool ParallelRefinement::Lane::neighbour_warm(std::span<const WindowSample> window,
                                              const FitSettings& settings, WarmStart& warm) {
  if (window.empty()) return false;
  const Finished before = owner.wait_finished(index - 1);
  if (!before) return false;
  auto at = std::find_if(bridge.begin(), bridge.end(),
                         [&](const WindowSample& s) { return s.t == neighbour_front_t; });
  if (at == bridge.end()) return false;
  warm = scp::refine::warm_start(*before, settings, *at);
  for (; std::next(at) != bridge.end() && at->t < window.front().t; ++at)
    scp::refine::shift(warm, *at, *std::next(at));
  return scp::refine::applicable(warm, window, settings) == WarmFallback::none;
}

ParallelRefinement::ParallelRefinement(const config::DaemonConfig& cfg, unsigned jobs,
                                       refine::FitObserver* observer, Applied applied)
    : settings_(cfg.refine),
      tolerance_s_(0.5 * cfg.loop.period_s),
      observer_(observer),
      applied_cb_(std::move(applied)),
      observed_(std::make_unique<SampleQueue>()),
      shadow_(std::make_unique<refine::Refiner>(cfg.refine, cfg.estimator, cfg.loop.period_s)) {
  if (observer_ != nullptr) shadow_->set_observer(observed_.get());
  view_.interval_s = settings_.interval_s;
  for (unsigned i = 0; i < std::max(jobs, 2U); ++i)
    lanes_.push_back(std::make_unique<Lane>(cfg, *this));
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
    Finished finished;
    try {
      lane.collect_bridge();
      for (const HandOff& h : lane.job) lane.refiner.accept(h);
      lane.calls = 0;
      lane.refiner.fit(lane.paper, lane.t, lane.job_wall_ns);
      finished = std::make_shared<const FitResult>(lane.fit);
    } catch (...) {
      lane.error = std::current_exception();  // rethrown where the fit is applied
    }
    lane.job.clear();
    lock.lock();
    finished_[lane.index] = std::move(finished);
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
  // With no fit under way the observer sees the samples now, as inline.
  if (made_.empty() && observer_ != nullptr) observed_->show(*observer_, observed_->pushed());
  // A new window (a break in the data): no fit in it yet, and no stall to wait out.
  if (shadow_->view().windows != window_) {
    window_ = shadow_->view().windows;
    fitted_in_window_ = false;
    rejected_wait_s_ = 0.0;
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
  return rejected_wait_s_ > 0.0 &&
         shadow_->window().back().t - stalled_t_end_ + tolerance_s_ < rejected_wait_s_;
}

void ParallelRefinement::after_cycle(HandOffRing& ring, double t,
                                     const refine::PaperEstimate& paper) {
  drain(ring);
  if (!due_by_interval()) return;
  // What the fit N before this one found decides whether it waits: only that fit, so that the
  // order in which the lanes finish never matters. After a fit that stalled, until one that does
  // not, the fits are made one at a time, each knowing the one before: on data the model does not
  // explain the wait then applies as inline, and costs one fit made too early, not N - 1 per stall.
  const std::uint64_t ahead = rejected_wait_s_ > 0.0 ? 1 : lanes_.size();
  if (dispatched_ >= ahead) apply_through(dispatched_ - ahead);
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

ParallelRefinement::Finished ParallelRefinement::wait_finished(std::uint64_t fit) {
  std::unique_lock lock(mutex_);
  done_.wait(lock, [&] { return stopping_ || finished_.count(fit) != 0; });
  const auto it = finished_.find(fit);
  return it == finished_.end() ? nullptr : it->second;
}

std::optional<double> ParallelRefinement::first_unapplied_t() const noexcept {
  if (made_.empty()) return std::nullopt;
  return made_.front().t;
}

// On the lane after the one that made the previous fit; that lane has applied its own last.
void ParallelRefinement::make_fit(double t, const refine::PaperEstimate& paper) {
  Lane& lane = *lanes_[dispatched_ % lanes_.size()];
  const double t_end = shadow_->window().back().t;
  const double front_t = shadow_->window().front().t;
  made_.push_back({observed_->pushed(), window_, t, t_end});
  {
    std::lock_guard lock(mutex_);
    lane.job.swap(lane.pending);  // the lane cleared its last job: `pending` starts empty
    lane.paper = paper;
    lane.t = t;
    lane.job_wall_ns = clock::unix_ns();
    lane.index = dispatched_;
    // Where the refiner offers no warm start (a link whose timing it estimates), nor does this.
    lane.has_neighbour = dispatched_ > 0 && !settings_.estimate_link_timing;
    lane.neighbour_front_t = last_front_t_;
    lane.front_t = front_t;
    lane.state = Lane::State::queued;
  }
  work_.notify_all();
  fitted_in_window_ = true;
  last_fit_t_end_ = t_end;
  last_front_t_ = front_t;
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
    observer_->on_fit(lane.fit, lane.fit_window_read, lane.wall_ns);
  }
  merge_view(lane);
  // The stall rule of Refiner::fit, for the fits made from now on in the same window.
  const bool stalled = lane.fit.stop == scp::refine::StopReason::stalled && made.window == window_;
  stalled_t_end_ = made.t_end;
  rejected_wait_s_ =
      stalled ? std::min(lane.fit.t_end - lane.fit.t_begin, settings_.window_s) : 0.0;
  if (applied_cb_) applied_cb_(view_);
  {
    std::lock_guard lock(mutex_);
    lane.state = Lane::State::idle;
    // The fit before this one can seed no other now.
    finished_.erase(finished_.begin(), finished_.lower_bound(applied_));
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
  // A warm refit started from a refined fit, whichever lane made it.
  if (latest.warm) merged.seed = refine::Seed::refined;
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

#pragma once
// The daemon's side of the output-error refinement (refine/fit.hpp): keeps the window of samples
// the loop handed off, decides when a fit is due, chooses where the solver starts, calls
// refine::fit and tests the paper law against the result. Single-threaded: the service's worker
// thread owns one (refine_worker.hpp); a batch run calls it inline between cycles, which makes it
// deterministic there.
//
// Each fit after the first of a window starts warm (refine/warm_start.hpp) from the previous one,
// carried along the samples the window drops; refine::fit runs the full fit when that does not
// apply, and the view says which (RefinedView::warm, warm_fallback).
//
// A window is one contiguous run of samples, never more: the model is simulated through it from
// one initial state, so a gap (a time step above refine.max_gap_s, a change of the
// loop's hand-off segment: a dropped sample, an estimator reset, the loop leaving RUNNING) empties
// it and the next fit waits until the new run spans refine.min_window_s.

#include <atomic>
#include <functional>
#include <span>
#include <vector>

#include "daemon/analysis/refine/refined_view.hpp"
#include "daemon/analysis/refine/sample_window.hpp"
#include "daemon/config/daemon_config.hpp"
#include "daemon/core/handoff.hpp"
#include "refine/fit.hpp"
#include "refine/warm_start.hpp"

namespace scp::daemon::refine {

using scp::refine::Vector6;

// The paper law's published estimate when a fit is made: a seed, and the estimate under test.
struct PaperEstimate {
  std::array<double, 6> theta_hat{};
  std::array<double, 6> sigma{};
};

using FitFunction = std::function<scp::refine::FitResult(
    std::span<const scp::refine::WindowSample>, const Vector6&, const scp::refine::FitSettings&)>;

// Who else reads the refinement's data (the health monitor, daemon/analysis/health/): every
// valid sample in time order, and every fit with the window it was made on. Called on the
// refinement's own thread, which also calls poll() between fits (the worker after every drain
// of the ring; a batch run every cycle) for work of its own.
class FitObserver {
 public:
  virtual ~FitObserver() = default;
  virtual void poll() {}
  virtual void on_sample(const scp::refine::WindowSample& sample) noexcept = 0;
  virtual void on_fit(const scp::refine::FitResult& fit,
                      std::span<const scp::refine::WindowSample> window, std::int64_t wall_ns) = 0;
};

class Refiner {
 public:
  // `fit` is refine::fit except in tests. Allocates the window: window_s / period_s samples.
  Refiner(const config::RefineSettings& settings, const estimator::EstimatorConfig& estimator,
          double period_s, FitFunction fit = scp::refine::fit);

  // One sample from the loop; a break in the data starts a new window first.
  void accept(const HandOff& handoff) noexcept;
  // Everything waiting in the ring; returns how many.
  std::size_t drain(HandOffRing& ring) noexcept;

  // The window spans min_window_s and interval_s of loop time passed since the last fit's data
  // (after a fit whose model the window rejected, refiner.cpp's model_rejected: the span of that
  // fit's window, up to window_s, if longer).
  bool due() const noexcept;
  // The window spans min_window_s and holds samples newer than the last fit (the end of a batch
  // run fits once more then).
  bool has_unfitted_data() const noexcept;

  // Fits the window now. `now_t` is the loop time, `wall_ns` the UTC wall clock (ns since the
  // epoch) put in the view.
  const RefinedView& fit(const PaperEstimate& paper, double now_t, std::int64_t wall_ns);

  // A flag the fit polls (refine::FitSettings::cancel): when it reads true a fit in progress
  // returns within about a millisecond, not converged. The service's worker points it at its stop
  // flag so that shutdown never waits on a fit; nullptr (the default) never cancels.
  void set_cancel(const std::atomic<bool>* cancel) noexcept { cancel_ = cancel; }

  // Sees every sample and fit from now on; nullptr (the default) for none. Must outlive the
  // refiner's use.
  void set_observer(FitObserver* observer) noexcept { observer_ = observer; }

  const RefinedView& view() const noexcept { return view_; }
  const SampleWindow& window() const noexcept { return window_; }
  // Where the next fit would start, and from which source: the last converged fit whose σ is
  // below |θ| for every free parameter, else the paper law's θ̂ when it has one, else theta0.
  Seed choose_seed(const PaperEstimate& paper, Vector6& start) const noexcept;

 private:
  bool window_ready() const noexcept;
  // After a fit whose model a window of span_s rejected, θ5 = λ/Cth its fitted cooling rate: loop
  // time until the window is full (it covered 1/θ5) or has grown fourfold, or once full renewed.
  double rejected_wait(double span_s, double theta5) const noexcept;
  void validate(scp::refine::FitResult& r, const PaperEstimate& paper,
                std::span<const scp::refine::WindowSample> prepared);
  scp::refine::FitSettings make_fit_settings() const;
  void note_converged(const scp::refine::FitResult& r, const PaperEstimate& paper);
  void drop_oldest() noexcept;

  config::RefineSettings settings_;
  Vector6 theta0_;
  std::array<bool, 6> known_;
  estimator::VoltageHold voltage_hold_;
  double max_gap_s_;
  double tolerance_s_;  // half a period: loop times are sums of periods, never exact
  FitFunction fit_;
  const std::atomic<bool>* cancel_ = nullptr;
  FitObserver* observer_ = nullptr;
  SampleWindow window_;
  // The window as the fit read it (refine::prepare_window: the voltage's hold and interval), for
  // the validations and the observer; reserved to the window's capacity.
  std::vector<scp::refine::WindowSample> prepared_;
  bool started_ = false;
  std::uint64_t segment_ = 0;
  bool fitted_in_window_ = false;
  double last_fit_t_end_ = 0.0;
  // After a fit whose model the window rejected: loop time the next fit waits for instead of
  // interval_s, when longer.
  double rejected_wait_s_ = 0.0;
  bool have_converged_ = false;
  Vector6 last_converged_ = Vector6::Zero();
  // The latest fit as a warm start (refine/warm_start.hpp), its trajectory stepped along as the
  // window drops its oldest samples, so that it sits at the window's first sample when the next
  // fit is due; none after a break in the data.
  scp::refine::WarmStart warm_;
  bool warm_held_ = false;
  RefinedView view_{};
};

}  // namespace scp::daemon::refine

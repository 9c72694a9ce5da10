#pragma once
// The daemon's side of the health monitor (health/monitor.hpp): fed by the refinement (each fit,
// each sample the loop handed off) on whatever thread runs it, the worker in the service, inline
// in a batch run (deterministic there). Below the loop's priority, never on the loop thread.
//
// The fast detector's residuals come from the refinement's own simulator: at each converged fit
// the fitted model is run through its window from the fitted initial state, and from the state
// it reaches at the window's end a SensitivitySimulator runs the monitor's reference θ forward
// on every later sample; r = ε/σ and J = ∂(y/σ)/∂θ with σ the fit's noise estimates, each
// widened by √ratio where the fit's own residuals vary over a block more than white noise does
// (health/block_variance.hpp). The next fit
// re-seeds it, so the open-loop simulation never runs longer than refine.interval_s plus a fit.

#include <optional>
#include <string>
#include <vector>

#include "daemon/analysis/health/baseline.hpp"
#include "daemon/analysis/health/health_view.hpp"
#include "daemon/analysis/refine/refiner.hpp"
#include "health/monitor.hpp"
#include "refine/model_simulator.hpp"
#include "refine/sensitivities.hpp"
#include "refine/sensor_lag.hpp"

namespace scp::daemon::health {

class HealthRunner final : public refine::FitObserver {
 public:
  explicit HealthRunner(const scp::health::HealthSettings& settings);

  // A new baseline (or none: the monitor stops, the state is blind). Restarts the monitor.
  void set_baseline(const std::optional<Baseline>& baseline, const std::string& source);
  // Without a baseline, the next converged fit of a window spanning at least `min_span_s`
  // becomes it (a batch run with no baseline file: changes are then found against the run's own
  // start). A full window, not the first short one: with the nuisance terms free a window shorter
  // than the thermal time scale leaves θ5, θ6 loose, a baseline that hides later changes.
  void adopt_first_fit(double min_span_s) noexcept {
    adopt_first_fit_ = true;
    adopt_min_span_s_ = min_span_s;
  }
  // The user has seen the latched state, at loop time t.
  void acknowledge(double t);

  void on_sample(const scp::refine::WindowSample& sample) noexcept override;
  void on_fit(const scp::refine::FitResult& fit, std::span<const scp::refine::WindowSample> window,
              std::int64_t wall_ns) override;

  // The monitor's events since the last call (journal, counters, a replay's summary).
  std::vector<scp::health::HealthEvent> take_events();
  const HealthView& view() const noexcept { return view_; }
  // The state for a recording's column: 0 blind, 1 ok, 2 drift, 3 changed.
  int state_code() const noexcept;

 private:
  void feed(const scp::refine::WindowSample& sample);
  void remember_fit(const scp::refine::FitResult& fit);
  void seed(const scp::refine::FitResult& fit, std::span<const scp::refine::WindowSample> window);
  void publish() noexcept;
  // The model's T̄ as the fit's sensor reads it at t: `sensed` (through the lag) plus the
  // fitted ambient offset and drift.
  double tbar_read(double sensed, double t) const noexcept;

  scp::health::HealthSettings settings_;
  bool adopt_first_fit_ = false;
  double adopt_min_span_s_ = 0.0;
  std::optional<scp::health::HealthMonitor> monitor_;
  // The residual simulator, seeded at the last converged fit's end.
  std::optional<scp::refine::SensitivitySimulator> simulator_;
  scp::refine::WindowSample last_sample_{};
  std::uint64_t generation_ = 0;
  std::uint64_t segment_ = 0;  // counts the simulator's seeds (the monitor's nuisance segments)
  double input_delay_ = 0.0;
  // The fit's nuisance terms (refine/fit_terms.hpp): the model's outputs plus x_zero, and
  // ambient_offset + ambient_drift·(t − t0) with t0 its window's first sample.
  double x_zero_ = 0.0, ambient_offset_ = 0.0, ambient_drift_ = 0.0, t0_ = 0.0;
  // The fit's extensions and its temperature sensor's lag (refine/sensor_lag.hpp), applied to
  // the simulated T̄ when lagged_.
  scp::refine::Tempcos tempcos_{};
  bool lagged_ = false;
  scp::refine::SensorLag lag_{0.0};
  scp::health::Vector2 inverse_sigma_ = scp::health::Vector2::Zero();
  HealthView view_{};
};

}  // namespace scp::daemon::health

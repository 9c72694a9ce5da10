#pragma once
// Actuator health: is the actuator still the one its baseline describes, and if not, what
// changed, by how much and since when. A pure class (no threads, clock or I/O): the caller passes
// loop times, refined windows and residual samples, and reads a report and a list of events.
//
// Three detectors share one false-alarm budget (HealthSettings::false_alarm_days, a third each):
// - fast: a two-sided CUSUM per parameter on the residuals' efficient scores (score_blocks.hpp)
//   with the reference's error estimated out by the residuals (their innovations,
//   innovation.hpp), thresholds from Siegmund's ARL (cusum.hpp); at an alarm its change-point
//   estimate is the onset, and the parameter is named once the residuals after it separate it
//   from the other candidates (naming.hpp) or the first window after the onset does (an event
//   `named`); until then the change carries its candidates.
// - sure: each refined window against the reference, a Wald χ² per block and a z per parameter
//   (wald.hpp), thresholds from the crossing rate of the overlapping windows' χ² process
//   (scan_threshold.hpp).
// - drift: each parameter's slope over the windows since the last change (trend.hpp).
//
// A slow drift against a fixed baseline eventually exceeds any χ² threshold, so `changed` is
// tested against the fixed baseline only once, on the first window (a change while nothing ran):
// after it the reference of both the fast and the sure detector is the trend of the live windows
// since the last change, extrapolated to the time tested, from windows that share no data with
// what is tested (with a slope as soon as two windows' midpoints span trend_min_span_s, its
// uncertainty carried into the tests). A drift then moves the reference with it and raises
// `drift` (its slope), not `changed`; a step departs from the extrapolation and raises
// `changed`. The deviation from the baseline itself is published with every window (how far
// the actuator is from its healthy self), never an alarm.
//
// The sure detector's alarm is held until a window lies entirely after its onset: a window's θ̂
// departs from the trend linearly across a step (the share of its data after it) but
// quadratically after a drift starts, and the two shapes fitted to the windows since then decide
// between `changed` and `drift` (a drift that starts late is not a step). The fast detector
// decides at once from its blocks: a step leaves a constant residual score, a drift that the
// reference has not caught up with a growing one.
//
// After a change at onset τ the windows that straddle τ leave the trends, and the detectors wait
// for the first window entirely after τ (one window length) to be their new reference. An alarm
// that may be the same parameters soon after that restart continues the change: one `drift`,
// then counted alarms without events (monitor_chain.cpp). `changed` and `drift` stay latched until
// acknowledge(); a drift is raised again only after its slopes have stayed within bounds for a
// window length and then left them again.

#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include "health/cusum.hpp"
#include "health/departure_shape.hpp"
#include "health/indicators.hpp"
#include "health/innovation.hpp"
#include "health/naming.hpp"
#include "health/score_blocks.hpp"
#include "health/settings.hpp"
#include "health/trend.hpp"
#include "health/types.hpp"
#include "health/wald.hpp"

namespace scp::health {

enum class State : std::uint8_t { ok, drift, changed };
const char* state_name(State state) noexcept;

enum class Detector : std::uint8_t { none, fast, sure };
const char* detector_name(Detector detector) noexcept;

// What the fast detector's residuals must be computed against at loop time t.
struct Reference {
  bool valid = false;  // false right after a change, until a window lies after it
  Vector6 theta = Vector6::Zero();
  Matrix6 covariance = Matrix6::Zero();
  // Increases whenever the reference is recomputed (each window): the caller re-seeds its
  // simulator with the new θ.
  std::uint64_t generation = 0;
};

// A change point: when it began and was found, by which detector, the parameter named first and
// every parameter's shift with σ (the single-parameter GLR's for the fast detector, the Wald
// test's for the sure one).
struct ChangePoint {
  double onset = 0.0;        // s, loop time
  double detected_at = 0.0;  // s
  Detector detector = Detector::none;
  int parameter = -1;  // named first; -1 while the data do not yet separate the candidates
  // The fast detector names a parameter only when the residuals since the onset separate it from
  // every other (naming.hpp); until then `parameter` is -1 and `candidates` is the set that
  // explains them alike, and an event `named` follows when the data decide.
  bool definite = true;
  ParameterMask candidates{};
  std::array<ParameterShift, kParams> parameters{};
};

struct ParameterTrend {
  bool tested = false;
  double per_hour = 0.0;  // slope, θ units per hour
  double sigma_per_hour = 0.0;
  double relative_per_hour = 0.0;  // slope / |θ_i|
  bool drifting = false;           // significant and beyond drift_per_hour
};

struct DriftReport {
  bool valid = false;  // a slope was fitted
  double data_span_s = 0.0;
  int windows = 0;
  double z_threshold = 0.0;
  std::array<ParameterTrend, kParams> parameters{};
};

struct FastReport {
  bool active = false;                  // a reference is valid and blocks arrive
  std::array<double, kParams> ratio{};  // max(g⁺, g⁻)/h per parameter (1: alarm)
  std::array<CusumDesign, kParams> design{};
  std::array<double, kParams> design_delay_s{};  // expected delay for design_change
  std::uint64_t blocks = 0;
};

// `named`: the parameter of a change raised without one (ChangePoint::definite false), once the
// data since its onset separate it from the other candidates.
enum class EventKind : std::uint8_t { changed, drift, acknowledged, named };
const char* event_name(EventKind kind) noexcept;

struct HealthEvent {
  EventKind kind = EventKind::changed;
  double t = 0.0;                               // loop time it was raised
  State state = State::ok;                      // the state after it
  ChangePoint change;                           // kind == changed or named
  std::array<ParameterTrend, kParams> trend{};  // kind == drift
};

struct HealthReport {
  State state = State::ok;
  double since = 0.0;  // loop time the state was entered (0: since the monitor started)
  bool has_change = false;
  ChangePoint change;  // the latest change point (its name once `named`)
  // The latest window against the baseline (published, never an alarm by itself) and against
  // the trend reference (the sure detector).
  bool has_window = false;
  WaldResult baseline_deviation;
  bool reference_tested = false;
  WaldResult reference_deviation;
  DriftReport drift;
  FastReport fast;
  Indicators indicators{};  // of the latest window
  Indicators baseline_indicators{};
  std::uint64_t windows = 0;           // windows given
  std::uint64_t windows_rejected = 0;  // non-finite, empty, or out of time order
  std::uint64_t changes = 0;
  std::uint64_t drifts = 0;
  std::uint64_t dismissed = 0;  // fast alarms whose named change was below min_relative_change
  // Alarms taken as a change going on (monitor_chain.cpp): the first raised `drift`.
  std::uint64_t drift_alarms = 0;
  std::uint64_t acknowledged = 0;
};

class HealthMonitor {
 public:
  // `baseline`: the refined window saved as healthy (its θ̂ and covariance; its times may be
  // from another run and are not used).
  HealthMonitor(const HealthSettings& settings, const WindowEstimate& baseline);

  // A converged refined window, in time order.
  void add_window(const WindowEstimate& window);

  // The reference model for the residuals at loop time t (see Reference).
  Reference reference_at(double t) const;
  // One sample of residuals against reference_at()'s θ: r = ε/σ per output, J = ∂(y/σ)/∂θ.
  void add_sample(double t, const Vector2& residual, const Matrix26& sensitivity);
  // The same with the nuisance's sensitivities N = ∂(y/σ)/∂[x0, ẋ0, T̄0, x offset, T̄ offset] of
  // the residual simulation seeded as `segment` (score_blocks.hpp): a caller that re-seeds its
  // simulator passes a new segment, and the naming of a change profiles each one's out.
  void add_sample(double t, const Vector2& residual, const Matrix26& sensitivity,
                  const Matrix2N& nuisance, std::uint64_t segment);
  // Or whole blocks, when the caller sums them itself.
  void add_block(const ScoreBlock& block);

  // The user has seen the latched state: back to ok.
  void acknowledge(double t);

  const HealthReport& report() const noexcept { return report_; }
  // The events since the last call (for the journal, the counters and a replay's summary).
  std::vector<HealthEvent> take_events();

  const WindowEstimate& baseline() const noexcept { return baseline_; }
  const HealthSettings& settings() const noexcept { return settings_; }

 private:
  struct Prediction {
    bool valid = false;
    bool from_baseline = false;
    TrendFit fit;
  };
  Prediction predict(double t, double data_before) const;
  void test_against_reference(const WindowEstimate& w);
  void update_drift(const WindowEstimate& w);
  void update_reference(double t);
  void design_cusums();
  void fast_alarm(const ScoreBlock& block);
  ChangePoint fast_change(const ChangeEvidence& since, const ScoreBlock& plain, double onset,
                          double t) const;
  void name_block(const ScoreBlock& block);
  void name_from_window(const WindowEstimate& w);
  void raise_name(const ChangePoint& change);
  void stop_naming() noexcept;
  TrendFit reference_for_naming(const WindowEstimate& w) const;
  bool spans_a_slope(std::span<const WindowEstimate> windows) const;
  double naming_start(double onset) const;
  NamingSettings naming_settings() const;
  bool late_drift(int parameter, double& onset);
  double step_onset(int parameter, double cusum_onset) const;
  bool blocks_show_drift(int parameter, double onset, ShapeFit& ramp) const;
  void raise_change(const ChangePoint& change);
  void push_change_event(EventKind kind, const ChangePoint& change);
  DriftReport assess_trend(std::span<const WindowEstimate> windows,
                           const WindowEstimate& latest) const;
  void raise_drift(double t, const std::array<ParameterTrend, kParams>& trend, double onset,
                   int parameter, const ParameterMask& candidates = {});
  void start_chain(const ChangePoint& change);
  bool absorbed_by_chain(const ChangePoint& change);
  void name_in_chain(const ChangePoint& change);
  void start_segment(double onset, double t);
  void confirm_pending(const WindowEstimate& w);
  void set_state(State state, double t);
  double window_onset_estimate(const WindowEstimate& w, int parameter, double delta) const;
  double sure_block_threshold(int block, const WindowEstimate& w, const Matrix6& c_ref) const;

  HealthSettings settings_;
  WindowEstimate baseline_;
  double rate_per_detector_;             // false alarms per second each detector may raise
  std::vector<WindowEstimate> history_;  // windows of the current segment, in time order
  // Every usable window of the last trend_span_s, across segments (a drift's slope).
  std::vector<WindowEstimate> all_windows_;
  // The latest change and the alarms of its parameters that continued it (monitor_chain.cpp).
  struct ChangeChain {
    bool active = false;
    ParameterMask parameters{};  // what its changes may be: names, else candidates
    double first_onset = 0.0;
    double last_detected = 0.0;
    bool drift_raised = false;
    void add(const ParameterMask& more) {
      for (int i = 0; i < kParams; ++i) parameters[i] = parameters[i] || more[i];
    }
  };
  ChangeChain chain_;
  double segment_start_;
  bool first_segment_ = true;
  bool tested_against_baseline_ = false;
  double last_window_end_;
  double last_window_length_ = 0.0;
  bool have_last_test_ = false;
  double last_test_end_ = 0.0;
  Vector6 last_test_delta_ = Vector6::Zero();
  bool drift_armed_ = true;
  double drift_clear_since_ = 0.0;  // NaN while drifting

  // The sure detector's alarm waiting for a window after its onset: a step or a late drift?
  struct PendingChange {
    bool active = false;
    ChangePoint change;
    TrendFit reference;  // the trend it departed from, frozen
    Matrix6 reference_covariance = Matrix6::Zero();
  };
  PendingChange pending_;

  // A fast alarm raised without a name: the residuals go on against the reference it departed
  // from (frozen) until they name the parameter or a window after the onset gives the new
  // reference; the windows after the onset that share no data name it, until one does or the
  // reference span has passed (monitor_naming.cpp).
  struct PendingName {
    bool active = false;  // by the residuals
    ChangePoint change;
    TrendFit reference;
    std::vector<ScoreBlock> blocks;  // since the onset
    bool by_windows = false;
    double next_window_from = 0.0;               // s: the next window to try begins here or later
    std::vector<WindowEstimate> windows_before;  // the reference's windows, before the onset
    std::vector<WindowEstimate> windows_after;   // those tried, which share no data
  };
  PendingName naming_;

  Reference reference_;
  TrendFit reference_fit_;  // reference_at() extrapolates its slope
  std::array<TwoSidedCusum, kParams> cusums_;
  int alarm_waits_ = 0;  // blocks an alarm has waited for evidence to name it (fast_alarm)
  // The blocks' scores with the reference's error estimated out (the CUSUMs' input).
  InnovationScores innovation_;
  BlockAccumulator accumulator_;
  std::vector<ScoreBlock> recent_blocks_;  // for the isolation since an onset, oldest first
  std::vector<std::pair<double, Vector6>> recent_z_;  // their start and the CUSUMs' input
  Matrix6 mean_information_ = Matrix6::Zero();        // per block, running mean
  std::uint64_t information_blocks_ = 0;

  HealthReport report_;
  std::vector<HealthEvent> events_;
};

}  // namespace scp::health

#pragma once
// What the refinement publishes (a Seqlock, like the loop's PublishedState) and what the socket
// server, the batch summary and the recorder read. Plain data: fixed sizes, no pointers.

#include <array>
#include <cmath>
#include <cstdint>

#include "common/names.hpp"
#include "refine/fit_terms.hpp"
#include "refine/validation.hpp"
#include "refine/warm_fallback.hpp"

namespace scp::daemon::refine {

// Where the solver started: the previous converged refined θ̂, the paper law's θ̂, or
// estimator.theta0.
enum class Seed : std::uint8_t { none, refined, paper, theta0 };

inline constexpr NameTable<Seed, 4> kSeedNames{{{Seed::none, "none"},
                                                {Seed::refined, "refined"},
                                                {Seed::paper, "paper"},
                                                {Seed::theta0, "theta0"}}};

constexpr const char* seed_name(Seed seed) noexcept {
  return name_of(kSeedNames, seed);
}

inline constexpr std::size_t kMessageChars = 128;

struct RefinedView {
  bool valid = false;      // at least one fit has finished; everything below describes the latest
  std::uint64_t fits = 0;  // fits finished, converged or not
  std::uint64_t converged_fits = 0;  //
  std::uint64_t windows = 0;         // windows started: the first, then one per gap
  std::uint64_t warm_fits = 0;       // fits that were warm refits (refine/warm_start.hpp)
  double interval_s = 0.0;           // refine.interval_s, for refined_is_best()

  double fitted_at_t = 0.0;            // loop time when the fit was made
  std::int64_t fitted_at_unix_ns = 0;  // wall clock (UTC) when it finished
  double duration_s = 0.0;             // wall time the fit took
  Seed seed = Seed::none;
  std::array<double, 6> theta_hat{};
  std::array<double, 6> sigma{};  // 0 for known parameters
  // The factor the batch-means check scaled each σ by (refine::FitResult::sigma_inflation).
  std::array<double, 6> sigma_inflation{1.0, 1.0, 1.0, 1.0, 1.0, 1.0};
  double t_begin = 0.0;  // loop time of the window's first and last samples
  double t_end = 0.0;
  std::uint64_t samples = 0;
  std::array<double, 2> residual_rms{};  // x in m, T̄ in °C
  std::array<double, 2> noise_sigma{};   // estimated sensor noise, same units
  // refine.link_timing: the voltage's delay relative to its recorded instants, its σ, and the
  // samples' RMS timing error (s).
  bool input_delay_estimated = false;
  double input_delay_s = 0.0;
  double input_delay_sigma_s = 0.0;
  double input_delay_sigma_inflation = 1.0;  // the batch-means check's factor on it
  double sample_timing_sigma_s = 0.0;
  std::uint64_t outliers = 0;  // samples the fit down-weighted (refine::FitResult::outliers)
  bool converged = false;
  int iterations = 0;
  int evaluations = 0;  // residual passes over the window
  // A warm refit from the previous fit, or why the full fit ran instead (not_requested: no
  // previous fit in this window).
  bool warm = false;
  scp::refine::WarmFallback warm_fallback = scp::refine::WarmFallback::not_requested;
  std::array<char, kMessageChars> message{};

  // The paper law's θ̂ and σ at the latest converged fit, tested against it (refine::test_against):
  // per block (mechanical, thermal), biased = its σ does not cover the difference. Held through
  // fits that do not converge; all false until one does.
  bool bias_tested = false;
  std::array<bool, 2> paper_biased{};
  std::array<double, 2> bias_statistic{};
  std::array<double, 2> bias_threshold{};

  // Issue 28: the voltage interval the fit used, the nuisance terms and extensions as it left
  // them, and the model validation of the latest fit (refine/validation.hpp): the refined fit's
  // own, and the paper law's θ̂ simulated through the same window (paper_validation.hpp).
  scp::refine::VoltageInterval voltage_interval = scp::refine::VoltageInterval::before;
  // Undetermined (estimated, not determined): the window could not tell the intervals apart, and
  // `best` keeps off the refined estimate (best.hpp).
  scp::refine::IntervalEvidence voltage_interval_evidence;
  scp::refine::SwitchPhase voltage_switches;  // FitResult::voltage_switches
  scp::refine::Nuisance nuisance;
  scp::refine::Extensions extensions;
  scp::refine::HeaterResistance heater;  // measured: the thermal input was the measured power
  bool validated = false;
  scp::refine::ValidationReport validation;
  bool paper_validated = false;
  scp::refine::ValidationReport paper_validation;
};

// Whether the latest fit estimated the voltage's interval and the window could not tell it
// (refine::IntervalEvidence): its θ1..θ4 are then a guess's.
inline bool interval_undetermined(const RefinedView& v) noexcept {
  const scp::refine::IntervalEvidence& e = v.voltage_interval_evidence;
  return e.estimated && !e.determined && !e.equivalent;
}

// Whether the latest fit's declared interval is one the window's data reject
// (refine::IntervalEvidence::contradicted): its θ1..θ4 are then the declaration's.
inline bool interval_contradicted(const RefinedView& v) noexcept {
  return v.voltage_interval_evidence.contradicted;
}

// Either: the latest fit's θ1..θ4 rest on an interval the data did not confirm.
inline bool interval_in_doubt(const RefinedView& v) noexcept {
  return interval_undetermined(v) || interval_contradicted(v);
}

// Whether the refined fit is current at loop time `now_t`: its latest fit converged, is at most 3
// intervals old and every σ is finite. Whether it is recommended also takes its validation
// (best_estimate, best.hpp).
inline bool refined_is_best(const RefinedView& v, double now_t) noexcept {
  if (!v.valid || !v.converged) return false;
  if (now_t - v.fitted_at_t > 3.0 * v.interval_s) return false;
  for (std::size_t i = 0; i < 6; ++i) {
    if (!std::isfinite(v.theta_hat[i]) || !std::isfinite(v.sigma[i])) return false;
  }
  return true;
}

}  // namespace scp::daemon::refine

#include "daemon/analysis/refine/refiner.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>

#include "daemon/analysis/refine/paper_validation.hpp"
#include "refine/validate_fit.hpp"
#include "refine/voltage_timing.hpp"

namespace scp::daemon::refine {

namespace {

std::size_t window_capacity(double window_s, double period_s) {
  return static_cast<std::size_t>(std::ceil(window_s / period_s)) + 1;
}

bool all_finite(const std::array<double, 6>& v) noexcept {
  return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
}

Vector6 to_vector(const std::array<double, 6>& v) noexcept {
  Vector6 out;
  for (int i = 0; i < 6; ++i) out[i] = v[static_cast<std::size_t>(i)];
  return out;
}

template <class Vec>
std::array<double, 6> to_array6(const Vec& v) noexcept {
  std::array<double, 6> out{};
  for (std::size_t i = 0; i < 6; ++i) out[i] = v[static_cast<Eigen::Index>(i)];
  return out;
}

bool well_determined(const Vector6& theta, const Vector6& sigma,
                     const std::array<bool, 6>& known) noexcept {
  for (int i = 0; i < 6; ++i) {
    if (known[static_cast<std::size_t>(i)]) continue;
    if (!std::isfinite(sigma[i]) || !(sigma[i] < std::abs(theta[i]))) return false;
  }
  return true;
}

bool usable(const PaperEstimate& paper) noexcept {
  return all_finite(paper.theta_hat) && std::any_of(paper.theta_hat.begin(), paper.theta_hat.end(),
                                                    [](double x) { return x != 0.0; });
}

// −2/N × the Gaussian log-likelihood with each channel's variance estimated (up to a constant):
// log σ̂x² + log σ̂T̄², comparable between two fits of one window.
double profile_cost(const scp::refine::FitResult& r) noexcept {
  constexpr double kTiny = 1e-300;
  return std::log(r.residual_rms[0] * r.residual_rms[0] + kTiny) +
         std::log(r.residual_rms[1] * r.residual_rms[1] + kTiny);
}

// Converged beats not converged; then the smaller profile cost.
bool better(const scp::refine::FitResult& a, const scp::refine::FitResult& b) noexcept {
  const bool fa = a.converged && a.theta.allFinite(), fb = b.converged && b.theta.allFinite();
  if (fa != fb) return fa;
  const double ca = profile_cost(a), cb = profile_cost(b);
  return std::isfinite(ca) && (!std::isfinite(cb) || ca < cb);
}

// What the fit found, into the view (plain copies; the counters and the bias test are the
// caller's).
void copy_result(const scp::refine::FitResult& r, RefinedView& v) noexcept {
  v.theta_hat = to_array6(r.theta);
  v.sigma = to_array6(r.sigma);
  v.sigma_inflation = to_array6(r.sigma_inflation);
  v.t_begin = r.t_begin;
  v.t_end = r.t_end;
  v.samples = r.samples;
  v.residual_rms = {r.residual_rms[0], r.residual_rms[1]};
  v.noise_sigma = {r.noise_sigma[0], r.noise_sigma[1]};
  v.input_delay_estimated = r.input_delay_estimated;
  v.input_delay_s = r.input_delay_s;
  v.input_delay_sigma_s = r.input_delay_sigma_s;
  v.input_delay_sigma_inflation = r.input_delay_sigma_inflation;
  v.sample_timing_sigma_s = r.sample_timing_sigma_s;
  v.outliers = r.outliers;
  // A result with a non-finite θ̂ is no result, whatever the solver said.
  v.converged = r.converged && all_finite(v.theta_hat);
  v.iterations = r.iterations;
  v.evaluations = r.evaluations;
  v.warm = r.warm;
  v.warm_fallback = r.warm_fallback;
  v.voltage_interval = r.voltage_interval;
  v.voltage_interval_evidence = r.voltage_interval_evidence;
  v.voltage_switches = r.voltage_switches;
  v.nuisance = r.nuisance;
  v.extensions = r.extensions;
  v.heater = r.heater;
  v.validated = r.validated;
  v.validation = r.validation;
  v.message.fill('\0');
  std::strncpy(v.message.data(), r.message != nullptr ? r.message : "", v.message.size() - 1);
}

// Whether the fit found a window its model cannot explain: it ended because the model could not
// follow the data (stalled on a pole beyond the sampling, unstable, or its passes' or sub-steps'
// budget spent on the way), or it converged to a solution the validation rejects (a `structure`
// verdict). Not a cancelled fit or an unusable window.
bool model_rejected(const scp::refine::FitResult& r) noexcept {
  using scp::refine::StopReason;
  if (r.stop == StopReason::stalled || r.stop == StopReason::work_budget_spent ||
      r.stop == StopReason::evaluation_budget_spent || r.stop == StopReason::model_unstable)
    return true;
  return r.converged && r.validated && r.validation.structure_found();
}

}  // namespace

Refiner::Refiner(const config::RefineSettings& settings,
                 const estimator::EstimatorConfig& estimator, double period_s, FitFunction fit)
    : settings_(settings),
      theta0_(estimator.theta0),
      known_(estimator.known),
      voltage_hold_(estimator.voltage_hold),
      max_gap_s_(settings.max_gap_s),
      tolerance_s_(0.5 * period_s),
      fit_(std::move(fit)),
      window_(window_capacity(settings.window_s, period_s)) {
  // Only a window the model reads differently needs its own copy (prepare_window): reserved
  // only then, as the daemon's locked memory makes every reserved page resident.
  if (!scp::refine::reads_as_recorded(voltage_hold_, settings.voltage_interval))
    prepared_.reserve(window_capacity(settings.window_s, period_s));
  view_.interval_s = settings.interval_s;
}

void Refiner::accept(const HandOff& handoff) noexcept {
  const scp::refine::WindowSample& s = handoff.sample;
  if (!std::isfinite(s.t) || !std::isfinite(s.x) || !std::isfinite(s.tbar) ||
      !std::isfinite(s.voltage)) {
    started_ = false;  // a hole in the data: the next valid sample starts a new window
    return;
  }
  bool restart = !started_ || handoff.segment != segment_;
  if (!restart && !window_.empty()) {
    const double step = s.t - window_.back().t;
    // Not one run: time went backwards or stood still, or the gap is longer than the voltage
    // during it can be trusted to have been held (refine.max_gap_s). The paper law restarts its
    // filters after estimator.max_gap_periods already; the output-error model needs no such
    // restart, and a window cut at every stall of a jittery link stays too short to fit.
    restart = !(step > 0.0) || step > max_gap_s_;
  }
  if (restart) {
    window_.clear();
    warm_held_ = false;
    fitted_in_window_ = false;
    rejected_wait_s_ = 0.0;
    ++view_.windows;
  }
  started_ = true;
  segment_ = handoff.segment;
  if (window_.size() == window_.capacity()) drop_oldest();  // push would drop it unseen
  window_.push(s);
  if (observer_ != nullptr) observer_->on_sample(s);
  // The window is window_s of loop time: with samples missing (overruns) fewer than its capacity.
  while (window_.size() > 1 && s.t - window_.front().t > settings_.window_s + tolerance_s_) {
    drop_oldest();
  }
}

void Refiner::drop_oldest() noexcept {
  if (warm_held_) scp::refine::shift(warm_, window_.front(), window_.at(1));
  window_.drop_oldest();
}

std::size_t Refiner::drain(HandOffRing& ring) noexcept {
  std::size_t n = 0;
  HandOff handoff;
  while (ring.try_pop(handoff)) {
    accept(handoff);
    ++n;
  }
  return n;
}

// After a rejection a full window waits to renew. A growing one that covered the thermal time
// constant 1/θ5 (the slowest the model has) waits to be full: its data did not fit, and each
// fit there is a full fit that stalls or crawls (at twice the length each time, 30, 60, 120,
// 240 s and the full window, a replay of a file the model does not explain cost 4x a clean
// one's: docs/numerics.md, "A fit the model cannot explain"). A shorter one may have failed for
// want of data (the first seconds of a run): it is retried at kRejectedGrowth times its length.
double Refiner::rejected_wait(double span_s, double theta5) const noexcept {
  constexpr double kRejectedGrowth = 4.0;
  const double to_full = settings_.window_s - span_s;
  if (!(to_full > tolerance_s_)) return settings_.window_s;
  const bool covered_thermal = theta5 > 0.0 && span_s * theta5 >= 1.0;
  return covered_thermal ? to_full : std::min((kRejectedGrowth - 1.0) * span_s, to_full);
}

bool Refiner::window_ready() const noexcept {
  return window_.size() >= 3 && window_.span_s() + tolerance_s_ >= settings_.min_window_s;
}

bool Refiner::due() const noexcept {
  if (!window_ready()) return false;
  if (!fitted_in_window_) return true;
  return window_.back().t - last_fit_t_end_ + tolerance_s_ >=
         std::max(settings_.interval_s, rejected_wait_s_);
}

bool Refiner::has_unfitted_data() const noexcept {
  return window_ready() && (!fitted_in_window_ || window_.back().t > last_fit_t_end_);
}

Seed Refiner::choose_seed(const PaperEstimate& paper, Vector6& start) const noexcept {
  Seed seed = Seed::theta0;
  start = theta0_;
  if (have_converged_) {
    seed = Seed::refined;
    start = last_converged_;
  } else if (usable(paper)) {
    seed = Seed::paper;
    start = to_vector(paper.theta_hat);
  }
  // Known parameters are held where the configuration puts them, whatever the seed says.
  for (int i = 0; i < 6; ++i) {
    if (known_[static_cast<std::size_t>(i)]) start[i] = theta0_[i];
  }
  return seed;
}

// Issue 28: every fit is validated (the fit's own final pass when it did, one more pass over the
// window otherwise), and the paper law's θ̂ is tested on the same window, both here on the
// worker's thread, never the loop's. `prepared` is the window as the fit read it.
void Refiner::validate(scp::refine::FitResult& r, const PaperEstimate& paper,
                       std::span<const scp::refine::WindowSample> prepared) {
  const scp::refine::Vector2 noise{settings_.declared_noise[0], settings_.declared_noise[1]};
  const bool cancelled = cancel_ != nullptr && cancel_->load(std::memory_order_relaxed);
  if (!r.validated && !cancelled && r.theta.allFinite() && !prepared.empty()) {
    scp::refine::ValidationSettings vs;
    vs.declared_noise = noise;
    r.validation = scp::refine::validate_fit(prepared, r, vs, known_);
    r.validated = true;
  }
  view_.paper_validated = false;
  if (!cancelled && usable(paper) && r.initial_state.allFinite() && !prepared.empty()) {
    view_.paper_validation = validate_paper(prepared, to_vector(paper.theta_hat), r.initial_state,
                                            r.input_delay_s, noise);
    view_.paper_validated = true;
  }
}

scp::refine::FitSettings Refiner::make_fit_settings() const {
  scp::refine::FitSettings fit_settings;
  fit_settings.max_iterations = settings_.max_iterations;
  fit_settings.known = known_;
  fit_settings.hac_lags = settings_.hac_lags;
  fit_settings.covariance_batches = settings_.covariance_batches;
  fit_settings.cancel = cancel_;
  fit_settings.max_input_delay_s =
      settings_.estimate_link_timing ? settings_.max_input_delay_s : 0.0;
  fit_settings.sample_timing_jitter = settings_.estimate_link_timing;
  fit_settings.outlier_threshold =
      settings_.estimate_link_timing ? scp::refine::kOutlierThreshold2d : 0.0;
  fit_settings.landing_timing_jitter = settings_.estimate_link_timing;
  fit_settings.voltage_hold = voltage_hold_;
  fit_settings.voltage_interval = settings_.voltage_interval;
  fit_settings.check_declared_interval = settings_.check_declared_interval;
  fit_settings.voltage_shape = settings_.voltage_shape;
  fit_settings.nuisance = settings_.nuisance;
  fit_settings.extensions = settings_.extensions;
  fit_settings.declared_noise = {settings_.declared_noise[0], settings_.declared_noise[1]};
  return fit_settings;
}

// A converged fit: counted, kept as the next seed when it determined θ, and the paper law tested
// against it.
void Refiner::note_converged(const scp::refine::FitResult& r, const PaperEstimate& paper) {
  RefinedView& v = view_;
  ++v.converged_fits;
  // A fit is a seed for the next window only if it determined every free θ to better than
  // its own size. A converged fit of a short, noisy window can sit in a far local minimum with a
  // σ that says so; seeding the next, longer fit from it keeps that minimum, where the paper
  // law's seed leads to the right one.
  if (well_determined(r.theta, r.sigma, known_)) {
    have_converged_ = true;
    last_converged_ = r.theta;
  }
  if (all_finite(paper.theta_hat) && all_finite(paper.sigma)) {
    const scp::refine::BiasTest test =
        scp::refine::test_against(r, to_vector(paper.theta_hat), to_vector(paper.sigma), known_);
    v.bias_tested = true;
    for (std::size_t b = 0; b < 2; ++b) {
      const auto i = static_cast<Eigen::Index>(b);
      v.bias_statistic[b] = test.statistic[i];
      v.bias_threshold[b] = test.threshold[i];
      v.paper_biased[b] = test.biased[b];
    }
  }
}

const RefinedView& Refiner::fit(const PaperEstimate& paper, double now_t, std::int64_t wall_ns) {
  Vector6 start;
  Seed seed = choose_seed(paper, start);
  scp::refine::FitSettings fit_settings = make_fit_settings();
  if (warm_held_) fit_settings.warm = &warm_;

  const auto begin = std::chrono::steady_clock::now();
  scp::refine::FitResult r = fit_(window_.samples(), start, fit_settings);
  // A second start when the previous window's fit led somewhere the data do not pin down: the
  // output-error cost has far local minima along the poorly excited common scale of θ1..θ4, where
  // a start from the paper law's estimate finds the right one. Both fit the same window; the
  // larger Gaussian likelihood wins.
  if (seed == Seed::refined && !well_determined(r.theta, r.sigma, known_) &&
      (cancel_ == nullptr || !cancel_->load(std::memory_order_relaxed)) && usable(paper)) {
    Vector6 other = to_vector(paper.theta_hat);
    for (int i = 0; i < 6; ++i) {
      if (known_[static_cast<std::size_t>(i)]) other[i] = theta0_[i];
    }
    fit_settings.warm = nullptr;
    scp::refine::FitResult r2 = fit_(window_.samples(), other, fit_settings);
    if (better(r2, r)) {
      r = r2;
      seed = Seed::paper;
    }
  }
  const std::span<const scp::refine::WindowSample> prepared =
      scp::refine::prepare_window(window_.samples(), voltage_hold_, r.voltage_interval, prepared_,
                                  settings_.voltage_shape, r.voltage_switches.phase);
  validate(r, paper, prepared);
  const double duration =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();

  fitted_in_window_ = true;
  last_fit_t_end_ = window_.empty() ? now_t : window_.back().t;
  // A window the model cannot explain: refitting one that is mostly the same data would end the
  // same way, at the cost of a whole budget (hundreds of passes) each interval, so the next
  // attempt waits for more data (rejected_wait). Its θ5 is the paper law's, which runs whatever
  // the fit makes of the window (a fit that went unstable may have taken θ5 anywhere).
  const double theta5 = usable(paper) && paper.theta_hat[4] > 0.0 ? paper.theta_hat[4] : r.theta[4];
  rejected_wait_s_ = model_rejected(r) ? rejected_wait(r.t_end - r.t_begin, theta5) : 0.0;
  // The next fit's warm start, whether or not this one converged (refine::fit declines one that
  // did not, and says so). None on a link whose timing the fit estimates: a warm refit would hold
  // the voltage's delay at the previous fit's and has not been shown sound beside the jitter and
  // landing filters there (one loaded run of the e2e link-timing test took a wrong solution for
  // converged); not held, it is not stepped along the window either.
  warm_held_ = !settings_.estimate_link_timing && !window_.empty() && r.theta.allFinite() &&
               r.initial_state.allFinite();
  if (warm_held_) warm_ = scp::refine::warm_start(r, fit_settings, window_.front());

  RefinedView& v = view_;
  v.valid = true;
  ++v.fits;
  v.fitted_at_t = now_t;
  v.fitted_at_unix_ns = wall_ns;
  v.duration_s = duration;
  v.seed = seed;
  copy_result(r, v);
  if (r.warm) ++v.warm_fits;

  if (v.converged) note_converged(r, paper);
  if (observer_ != nullptr) observer_->on_fit(r, prepared, wall_ns);
  return view_;
}

}  // namespace scp::daemon::refine

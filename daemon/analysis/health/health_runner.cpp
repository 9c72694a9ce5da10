#include "daemon/analysis/health/health_runner.hpp"

#include <cmath>
#include <cstring>

#include "health/block_variance.hpp"
#include "refine/model_simulator.hpp"

namespace scp::daemon::health {

namespace {

using scp::health::HealthMonitor;
using scp::health::Matrix26;
using scp::health::Matrix2N;
using scp::health::Vector2;
using scp::refine::Verdict;

const char* combined_verdict(const scp::refine::FitResult& fit) noexcept {
  if (!fit.validated) return "untested";
  const Verdict m = fit.validation.mechanical.verdict, t = fit.validation.thermal.verdict;
  if (m == Verdict::kAdequate && t == Verdict::kAdequate) return "adequate";
  // The worse of the two: structure over coloured noise over untested.
  for (const Verdict v : {Verdict::kStructure, Verdict::kNoiseColored, Verdict::kUntested}) {
    if (m == v || t == v) return scp::refine::verdict_name(v);
  }
  return "untested";
}

template <std::size_t N>
void copy_text(std::array<char, N>& out, const std::string& text) noexcept {
  out.fill('\0');
  std::strncpy(out.data(), text.c_str(), N - 1);
}

}  // namespace

HealthRunner::HealthRunner(const scp::health::HealthSettings& settings) : settings_(settings) {}

void HealthRunner::set_baseline(const std::optional<Baseline>& baseline,
                                const std::string& source) {
  monitor_.reset();
  simulator_.reset();
  view_.baseline_present = baseline.has_value();
  view_.report = {};
  view_.last_window_unix_ns = 0;
  copy_text(view_.baseline_file, baseline ? source : std::string());
  if (baseline) {
    const scp::health::WindowEstimate& w = baseline->window;
    for (int i = 0; i < 6; ++i) {
      view_.baseline_theta[static_cast<std::size_t>(i)] = w.theta[i];
      view_.baseline_sigma[static_cast<std::size_t>(i)] =
          std::sqrt(std::max(0.0, w.covariance(i, i)));
    }
    view_.baseline_t_begin = w.t_begin;
    view_.baseline_t_end = w.t_end;
    view_.baseline_saved_unix_ns = baseline->saved_unix_ns;
    monitor_.emplace(settings_, w);
  }
  publish();
}

void HealthRunner::acknowledge(double t) {
  if (monitor_) monitor_->acknowledge(t);
  publish();
}

void HealthRunner::on_sample(const scp::refine::WindowSample& sample) noexcept {
  try {
    feed(sample);
  } catch (...) {
    simulator_.reset();  // only the monitor's block history allocates: wait for the next fit
  }
}

void HealthRunner::feed(const scp::refine::WindowSample& sample) {
  if (!monitor_ || !simulator_ || !(sample.t > last_sample_.t)) return;
  const scp::health::Reference reference = monitor_->reference_at(sample.t);
  if (!reference.valid) {
    last_sample_ = sample;
    return;
  }
  if (reference.generation != generation_) {
    // The reference moved (a new window): carry on from the simulated state with the new θ.
    const scp::refine::ModelState s = simulator_->state();
    simulator_.emplace(reference.theta, scp::refine::InitialState(s.x, s.xdot, s.tbar), false,
                       tempcos_);
    if (lagged_) lag_.resume(lag_.reading(), s.tbar, &simulator_->dtbar());
    generation_ = reference.generation;
    ++segment_;
  }
  const double dt = sample.t - last_sample_.t;
  simulator_->advance(last_sample_, sample, input_delay_);
  last_sample_ = sample;
  const scp::refine::ModelState& s = simulator_->state();
  if (lagged_) lag_.advance(dt, s.tbar, &simulator_->dtbar());
  // T̄ as the fit's sensor reads it (refine/sensor_lag.hpp), and its sensitivities.
  const scp::refine::ParamVector& dtbar_read = lagged_ ? lag_.sensitivities() : simulator_->dtbar();
  const double x_model = s.x + x_zero_;
  const double tbar_model = tbar_read(lagged_ ? lag_.reading() : s.tbar, sample.t);
  const Vector2 residual((sample.x - x_model) * inverse_sigma_[0],
                         (sample.tbar - tbar_model) * inverse_sigma_[1]);
  Matrix26 sensitivity;
  sensitivity.row(0) = simulator_->dx().head<6>().transpose() * inverse_sigma_[0];
  sensitivity.row(1) = dtbar_read.head<6>().transpose() * inverse_sigma_[1];
  // The nuisance: the state at the seed (the simulator's last three parameters) and the offsets.
  Matrix2N nuisance = Matrix2N::Zero();
  nuisance.row(0).head<3>() =
      simulator_->dx().segment<3>(scp::refine::kX0).transpose() * inverse_sigma_[0];
  nuisance.row(1).head<3>() =
      dtbar_read.segment<3>(scp::refine::kX0).transpose() * inverse_sigma_[1];
  nuisance(0, 3) = inverse_sigma_[0];
  nuisance(1, 4) = inverse_sigma_[1];
  if (!residual.allFinite() || !sensitivity.allFinite() || !nuisance.allFinite()) {
    simulator_.reset();  // diverged: wait for the next fit
    return;
  }
  monitor_->add_sample(sample.t, residual, sensitivity, nuisance, segment_);
  ++view_.residual_samples;
}

void HealthRunner::on_fit(const scp::refine::FitResult& fit,
                          std::span<const scp::refine::WindowSample> window, std::int64_t wall_ns) {
  const bool usable =
      fit.converged && fit.theta.allFinite() && fit.covariance.allFinite() && !window.empty();
  if (!usable) return;
  remember_fit(fit);
  if (!monitor_ && adopt_first_fit_ && fit.t_end - fit.t_begin >= adopt_min_span_s_) {
    Baseline first;
    first.window = {fit.t_begin, fit.t_end, fit.theta, fit.covariance};
    first.verdict = view_.fit_verdict.data();
    set_baseline(first, "the run's first converged full window");
    adopt_first_fit_ = false;
  }
  if (monitor_) {
    scp::health::WindowEstimate w;
    w.t_begin = fit.t_begin;
    w.t_end = fit.t_end;
    w.theta = fit.theta;
    w.covariance = fit.covariance;
    w.misfit = {fit.validated && fit.validation.mechanical.verdict != Verdict::kAdequate,
                fit.validated && fit.validation.thermal.verdict != Verdict::kAdequate};
    monitor_->add_window(w);
    view_.last_window_unix_ns = wall_ns;
    seed(fit, window);
  }
  publish();
}

void HealthRunner::remember_fit(const scp::refine::FitResult& fit) {
  view_.fit_present = true;
  view_.fit_t_begin = fit.t_begin;
  view_.fit_t_end = fit.t_end;
  for (int i = 0; i < 6; ++i) {
    view_.fit_theta[static_cast<std::size_t>(i)] = fit.theta[i];
    for (int k = 0; k < 6; ++k)
      view_.fit_covariance[static_cast<std::size_t>(6 * i + k)] = fit.covariance(i, k);
  }
  view_.fit_validated = fit.validated;
  copy_text(view_.fit_verdict, combined_verdict(fit));
}

void HealthRunner::seed(const scp::refine::FitResult& fit,
                        std::span<const scp::refine::WindowSample> window) {
  simulator_.reset();
  const double sx = fit.noise_sigma[0], st = fit.noise_sigma[1];
  if (!(sx > 0.0) || !(st > 0.0) || !std::isfinite(sx) || !std::isfinite(st)) return;
  // The fitted model through its own window, to the state at its last sample.
  // Stepped, not refine::simulate: only the last state is wanted, and a state per sample of a
  // 300 s window would be 7 MB of locked memory.
  // The temperature sensor's lag as the fit estimated it (or was told it) runs beside it, as in
  // the fit's residuals: without it a lagging sensor's T̄ residual is τs·dT̄/dt, a systematic
  // part the detectors would take for a change.
  scp::refine::ModelState state{fit.initial_state[0], fit.initial_state[1], fit.initial_state[2]};
  scp::refine::ThermalCache cache;
  tempcos_ = scp::refine::tempcos_of(fit.extensions);
  const double tau = fit.nuisance.sensor_lag.value;
  lagged_ = std::isfinite(tau) && tau != 0.0;  // as the fit: τs < 0 is its first-order continuation
  lag_ = scp::refine::SensorLag(lagged_ ? tau : 0.0);
  lag_.start(state.tbar, nullptr);
  x_zero_ = fit.nuisance.x_zero.value;
  ambient_offset_ = fit.nuisance.ambient_offset.value;
  ambient_drift_ = fit.nuisance.ambient_drift.value;
  t0_ = window.front().t;
  // The fit's own residuals on the way: how far they are from white at the detector's block
  // length (coloured sensor noise, a misfit the model leaves), which the scores must allow for.
  scp::health::BlockVarianceRatio ratio_x(settings_.block_s), ratio_t(settings_.block_s);
  for (std::size_t i = 1; i < window.size(); ++i) {
    scp::refine::advance_interval(fit.theta, window[i - 1], window[i], fit.input_delay_s, state,
                                  cache, nullptr, tempcos_);
    if (lagged_) lag_.advance(window[i].t - window[i - 1].t, state.tbar, nullptr);
    const double t = window[i].t;
    ratio_x.add(t, (window[i].x - (state.x + x_zero_)) / sx);
    ratio_t.add(t, (window[i].tbar - tbar_read(lagged_ ? lag_.reading() : state.tbar, t)) / st);
  }
  view_.residual_variance_ratio = {ratio_x.significant_ratio(), ratio_t.significant_ratio()};
  const scp::health::Reference reference = monitor_->reference_at(window.back().t);
  if (!reference.valid) return;
  // The reference's θ with the fit's extensions (a baseline holds θ only).
  simulator_.emplace(reference.theta, scp::refine::InitialState(state.x, state.xdot, state.tbar),
                     false, tempcos_);
  if (lagged_) lag_.resume(lag_.reading(), state.tbar, &simulator_->dtbar());
  generation_ = reference.generation;
  ++segment_;
  last_sample_ = window.back();
  input_delay_ = fit.input_delay_s;
  inverse_sigma_ = Vector2(1.0 / (sx * std::sqrt(view_.residual_variance_ratio[0])),
                           1.0 / (st * std::sqrt(view_.residual_variance_ratio[1])));
  ++view_.reseeds;
}

double HealthRunner::tbar_read(double sensed, double t) const noexcept {
  return sensed + ambient_offset_ + ambient_drift_ * (t - t0_);
}

std::vector<scp::health::HealthEvent> HealthRunner::take_events() {
  std::vector<scp::health::HealthEvent> events;
  if (monitor_) events = monitor_->take_events();
  publish();
  return events;
}

void HealthRunner::publish() noexcept {
  if (monitor_) view_.report = monitor_->report();
}

int HealthRunner::state_code() const noexcept {
  if (!monitor_) return 0;
  return 1 + static_cast<int>(monitor_->report().state);
}

}  // namespace scp::daemon::health

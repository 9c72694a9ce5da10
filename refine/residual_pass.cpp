#include "refine/residual_pass.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

#include "refine/landing_filter.hpp"
#include "refine/outer_update.hpp"
#include "refine/sensitivities.hpp"
#include "refine/sensor_lag.hpp"
#include "refine/validate_fit.hpp"
#include "refine/validation.hpp"

namespace scp::refine {

namespace {

using namespace outer_update;

// x's and T̄'s rows of one sample into JᵀWJ's upper triangle, over the slots they can touch
// (x never sees the sensor's lag).
// `hx` and `ht` may be one matrix.
inline void add_rows(ParamMatrix& hx, ParamMatrix& ht, const ParamVector& jx, double wx,
                     const ParamVector& jt, double wt, const PassSettings& settings) noexcept {
  if (settings.extensions) {
    if (wx != 0.0) add_outer_upper<kXRowSlotsExtended>(hx, jx, wx);
    if (wt != 0.0) add_outer_upper<kTbarRowSlotsExtended>(ht, jt, wt);
    return;
  }
  if (wx != 0.0) add_outer_upper<kXRowSlots>(hx, jx, wx);
  if (wt == 0.0) return;
  if (settings.sensor_lag) {
    add_outer_upper<kTbarRowSlotsLagged>(ht, jt, wt);
  } else {
    add_outer_upper<kTbarRowSlots>(ht, jt, wt);
  }
}

// Overlapping batch means: Σ over windows of B consecutive scores of (Σ s)(Σ s)ᵀ/B equals the
// Bartlett-weighted sum of the score's autocovariances with bandwidth B (Newey–West), at one
// rank-one update per sample whatever B is: its upper triangle, over the slots the score can
// reach (without the optional ones, 78 products of the 256 a full outer product takes).
class LongRunAccumulator {
 public:
  LongRunAccumulator(int bandwidth, bool optional_slots)
      : bandwidth_(std::max(1, bandwidth)),
        optional_(optional_slots),
        ring_(static_cast<std::size_t>(bandwidth_)) {}

  void add(const ParamVector& score) {
    ParamVector& slot = ring_[static_cast<std::size_t>(count_ % bandwidth_)];
    if (count_ >= bandwidth_) window_sum_ -= slot;
    slot = score;
    window_sum_ += score;
    ++count_;
    if (count_ >= bandwidth_) {
      if (optional_) {
        add_outer_upper<kAllSlots>(sum_, window_sum_, 1.0);
      } else {
        add_outer_upper<kBaseSlots>(sum_, window_sum_, 1.0);
      }
      ++windows_;
    }
  }

  // Scaled to the N samples (the N − B + 1 full windows stand for all N).
  ParamMatrix result() const {
    if (windows_ == 0) return ParamMatrix::Zero();
    const ParamMatrix full = sum_.selfadjointView<Eigen::Upper>();
    return full * (static_cast<double>(count_) /
                   (static_cast<double>(windows_) * static_cast<double>(bandwidth_)));
  }

 private:
  long bandwidth_;
  bool optional_;
  std::vector<ParamVector> ring_;
  ParamVector window_sum_ = ParamVector::Zero();
  ParamMatrix sum_ = ParamMatrix::Zero();
  long count_ = 0;
  long windows_ = 0;
};

// PassSettings::batches: the score, the information and the cost summed over K contiguous
// batches of (nearly) equal sample count, for PassResult::batch_scores, batch_information and
// batch_costs. The information and the cost are jtwj's and cost's growth over the batch (jtwj is
// accumulated in its upper triangle). The pass's loop touches it only at a batch's first sample
// and through the pointer begin_batch() returns, so that a pass without batches runs as fast as
// before it existed.
class BatchSums {
 public:
  BatchSums(int batches, std::size_t samples)
      : batches_(batches > 1 && samples >= static_cast<std::size_t>(batches)
                     ? static_cast<std::size_t>(batches)
                     : 0),
        samples_(samples),
        next_start_(batches_ > 0 ? 0 : std::numeric_limits<std::size_t>::max()),
        scores_(batches_, ParamVector::Zero()),
        information_(batches_, ParamMatrix::Zero()),
        costs_(batches_, 0.0) {}

  // The first sample of the next batch (never, without batches).
  std::size_t next_start() const { return next_start_; }

  // At sample k = next_start(), before its contributions to `jtwj` and `cost` (the cost so far
  // without sample k's): closes the batch before and returns where this one's score is summed.
  ParamVector* begin_batch(std::size_t k, const ParamMatrix& jtwj, double cost) {
    finish(jtwj, cost);
    current_ = k * batches_ / samples_;
    open_ = true;
    jtwj_at_start_ = jtwj;
    cost_at_start_ = cost;
    const std::size_t b = current_ + 1;  // the first k with k·K/N ≥ b
    next_start_ = b >= batches_ ? std::numeric_limits<std::size_t>::max()
                                : (b * samples_ + batches_ - 1) / batches_;
    return &scores_[current_];
  }

  // After the last sample: closes the open batch.
  void finish(const ParamMatrix& jtwj, double cost) {
    if (!open_) return;
    const ParamMatrix h = jtwj - jtwj_at_start_;
    information_[current_] = h.selfadjointView<Eigen::Upper>();
    costs_[current_] = cost - cost_at_start_;
    open_ = false;
  }

  void move_into(PassResult& r) {
    r.batch_scores = std::move(scores_);
    r.batch_information = std::move(information_);
    r.batch_costs = std::move(costs_);
  }

 private:
  std::size_t batches_;
  std::size_t samples_;
  std::size_t next_start_;
  std::vector<ParamVector> scores_;
  std::vector<ParamMatrix> information_;
  std::vector<double> costs_;
  std::size_t current_ = 0;
  bool open_ = false;
  ParamMatrix jtwj_at_start_ = ParamMatrix::Zero();
  double cost_at_start_ = 0.0;
};

// Hampel's three-part weight of a sample whose residual r (at the reference trajectory) has the
// weight matrix W = [w_xx w_xt; w_xt w_tt], m = √(rᵀWr), a = threshold: 1 up to a; a/m (Huber's)
// up to 2a; then falling linearly to 0 at 3a, beyond which the sample does not count. A Gaussian
// two-channel residual lies beyond 2a = 6.1 with probability 1e-8, so the descending part is for
// gross errors only, which then pull with no force at all. Huber's a/m alone let stamps displaced
// by milliseconds pull θ1..θ4 and the jitter estimate (docs/numerics.md, "Time on a real link",
// robust weights).
double outlier_weight(double threshold, double rx, double rt, double w_xx, double w_xt,
                      double w_tt) {
  if (threshold <= 0.0) return 1.0;
  const double m2 = w_xx * rx * rx + 2.0 * w_xt * rx * rt + w_tt * rt * rt;
  if (!(m2 > threshold * threshold)) return 1.0;
  const double m = std::sqrt(m2);
  if (!(m < 3.0 * threshold)) return 0.0;
  const double huber = threshold / m;
  return m <= 2.0 * threshold ? huber : huber * (3.0 * threshold - m) / threshold;
}

// PassSettings::landing_jitter: how long before `cur` the voltage switched inside (prev, cur]
// (0: at the sample, or not at all: voltage_since not after prev.t has no landing of its own).
double since_landing(const WindowSample& prev, const WindowSample& cur, double input_delay) {
  const double switch_at = cur.voltage_since + input_delay;
  if (!(cur.voltage_since > prev.t) || !(switch_at < cur.t)) return 0.0;
  return cur.t - switch_at;
}

// E[min(m², c²)]/E[m²] for m² ~ χ²₂ (two channels): 1 − e^{−c²/2}; 1 without a threshold.
double outlier_consistency(double threshold) {
  return threshold > 0.0 ? -std::expm1(-0.5 * threshold * threshold) : 1.0;
}

// PassSettings::validator: sample k as the pass sees it (rx, rt its residuals).
void feed_validator(ResidualValidator& v, std::span<const WindowSample> window, std::size_t k,
                    const SensitivitySimulator& sim, const ParamVector& jx, const ParamVector& jt,
                    double rx, double rt, double input_delay) {
  const WindowSample& w = window[k];
  ValidationSample s;
  s.t = w.t;
  s.x = w.x;
  s.x_model = w.x - rx;
  s.tbar = w.tbar;
  s.tbar_model = w.tbar - rt;
  s.thermal_input =
      k > 0 ? mean_square_voltage(window[k - 1], w, input_delay) : w.voltage * w.voltage;
  s.mechanical_input = sim.state().tbar;
  s.jacobian_x = std::span<const double>(jx.data(), kParams);
  s.jacobian_tbar = std::span<const double>(jt.data(), kParams);
  v.add(s);
}

// The residual bookkeeping shared by both passes: measured − the model's outputs, the simulation's
// plus p's nuisance terms.
struct ResidualSums {
  PassResult& r;
  double wx, wt;
  const ParamVector& p;
  double t0;  // the window's first sample: the ambient drift's origin
  double prev_rx = 0.0, prev_rt = 0.0;

  // `tbar_read`: the model's T̄ as its sensor reads it (refine/sensor_lag.hpp; s.tbar without a
  // lag).
  void add(std::size_t k, const WindowSample& w, const ModelState& s, double tbar_read, double& rx,
           double& rt) {
    rx = w.x - x_output(p, s.x);
    rt = w.tbar - tbar_output(p, tbar_read, w.t - t0);
    r.tbar_min = std::min(r.tbar_min, s.tbar);
    r.tbar_max = std::max(r.tbar_max, s.tbar);
    r.cost += wx * rx * rx + wt * rt * rt;
    r.rss[0] += rx * rx;
    r.rss[1] += rt * rt;
    if (k > 0) {
      r.lag1[0] += rx * prev_rx;
      r.lag1[1] += rt * prev_rt;
    }
    prev_rx = rx;
    prev_rt = rt;
  }
};

// Whether the pass gives up at sample k: cancelled by the caller, over the sub-step budget, or a
// state that has left the finite numbers (the rest of the window cannot bring it back).
bool give_up(const PassSettings& settings, std::size_t k, long substeps, const ModelState& s,
             PassResult& r) {
  if (settings.cancel != nullptr && k % kCancelStride == 0 &&
      settings.cancel->load(std::memory_order_relaxed)) {
    r.cancelled = true;
    return true;
  }
  if (settings.max_substeps > 0 && substeps > settings.max_substeps) {
    r.too_stiff = true;
    return true;
  }
  return !std::isfinite(s.x) || !std::isfinite(s.xdot) || !std::isfinite(s.tbar);
}

// Cost only: the state alone, about three times cheaper than with nine sensitivities. Returns
// whether it gave up.
bool cost_only_pass(std::span<const WindowSample> window, const ParamVector& p,
                    const PassSettings& settings, ResidualSums& sums) {
  const Vector6 theta = theta_of(p);
  const Tempcos tc = tempcos_of(p);
  const InitialState initial = initial_state_of(p);
  PassResult& r = sums.r;
  ModelState s{initial[0], initial[1], initial[2]};
  ThermalCache cache;
  SensorLag lag(p[kSensorLagSlot]);
  const bool lagged = p[kSensorLagSlot] != 0.0;
  lag.start(s.tbar, nullptr);
  double rx = 0.0, rt = 0.0;
  for (std::size_t k = 0; k < window.size(); ++k) {
    if (k > 0 && settings.thermal_only) {
      Piece pieces[2];
      const int n = pieces_between(window[k - 1], window[k], pieces, settings.input_delay);
      for (int i = 0; i < n; ++i) advance_thermal_piece(theta, pieces[i], s, cache, tc);
    } else if (k > 0) {
      r.substeps += advance_interval(theta, window[k - 1], window[k], settings.input_delay, s,
                                     cache, nullptr, tc);
    }
    if (give_up(settings, k, r.substeps, s, r)) return true;
    const double read =
        lagged && k > 0 ? lag.advance(window[k].t - window[k - 1].t, s.tbar, nullptr) : s.tbar;
    sums.add(k, window[k], s, read, rx, rt);
  }
  return false;
}

// PassSettings::timing: the trajectory the timing weights come from (timing_reference, not p),
// advanced beside the simulation, with the landing filter (PassSettings::landing_jitter) on it.
struct Reference {
  Reference(const PassSettings& settings, bool with_landing_filter)
      : theta(theta_of(settings.timing_reference)),
        tc(tempcos_of(settings.timing_reference)),
        state{settings.timing_reference[kX0], settings.timing_reference[kXdot0],
              settings.timing_reference[kTbar0]},
        landing(with_landing_filter) {}

  void advance(const WindowSample& prev, const WindowSample& cur, const PassSettings& settings) {
    const ModelState before = state;
    advance_interval(theta, prev, cur, settings.input_delay, state, cache, &u, tc);
    if (!landing) return;
    const SwitchLevels levels = switch_levels(prev, cur, settings.input_delay);
    const double du = levels.after - levels.before;
    filter.predict(theta, before, state, cur.t - prev.t,
                   since_landing(prev, cur, settings.input_delay), theta[kHeating] * du,
                   settings.timing_variance);
  }

  // The reference's residuals at `sample` (its outputs with the reference's nuisance terms).
  double x_residual(const WindowSample& sample, const PassSettings& settings) const {
    return sample.x - x_output(settings.timing_reference, state.x);
  }
  double tbar_residual(const WindowSample& sample, const PassSettings& settings, double t0) const {
    return sample.tbar - tbar_output(settings.timing_reference, state.tbar, sample.t - t0);
  }

  // The trajectory's velocity g = (ẋ, dT̄/dt) at the sample.
  Eigen::Vector2d velocity() const {
    return {state.xdot, linearize_thermal(theta, tc, state.tbar, u).f0};
  }

  Vector6 theta;
  Tempcos tc;
  ModelState state;
  ThermalCache cache;
  double u = 0.0;  // V² in effect at the sample
  bool landing;
  LandingFilter filter;
};

// What one timing-weighted sample contributed: its score J_kᵀW r_k (times its robust weight ω).
struct WeightedSample {
  ParamVector score;
  double omega = 1.0;  // the robust weight
  double gt = 0.0;     // dT̄/dt of the reference at the sample
};

// PassSettings::timing: one sample's residual r = (rx, rt) with the covariance C = Σ + P + s·g gᵀ:
// the sensors' Σ = diag(σx², σT̄²), the landing filter's prediction covariance P of (x, T̄) (0
// without the landings' jitter) and the stamp's s·g gᵀ; the sample counts with W = C⁻¹ over the
// channels the fit weights, and ω Hampel's weight of its residual at the reference. Adds it to
// JᵀWJ and the cost (which ResidualSums counted as wx·rx² + wt·rt²), and its share of the
// variances' Fisher scoring.
WeightedSample add_timing_weighted(const PassSettings& settings, double wx, double wt,
                                   const Reference& ref, const WindowSample& sample, double t0,
                                   double rx, double rt, const ParamVector& jx,
                                   const ParamVector& jt, PassResult& r) {
  const double s = settings.timing_variance;
  const Eigen::Vector2d g = ref.velocity();
  const Eigen::Matrix2d pred =
      ref.landing ? ref.filter.output_covariance() : Eigen::Matrix2d::Zero().eval();
  Eigen::Matrix2d c = pred + s * g * g.transpose();
  if (wx > 0.0) c(0, 0) += 1.0 / wx;
  if (wt > 0.0) c(1, 1) += 1.0 / wt;
  Eigen::Matrix2d w = Eigen::Matrix2d::Zero();
  if (wx > 0.0 && wt > 0.0) {
    const double det = c(0, 0) * c(1, 1) - c(0, 1) * c(1, 0);  // > 0: Σ is definite
    w << c(1, 1) / det, -c(0, 1) / det, -c(1, 0) / det, c(0, 0) / det;
  } else if (wx > 0.0) {
    w(0, 0) = 1.0 / c(0, 0);
  } else if (wt > 0.0) {
    w(1, 1) = 1.0 / c(1, 1);
  }
  const double w_xx = w(0, 0), w_xt = w(0, 1), w_tt = w(1, 1);
  const double omega = outlier_weight(settings.outlier_threshold, ref.x_residual(sample, settings),
                                      ref.tbar_residual(sample, settings, t0), w_xx, w_xt, w_tt);
  if (omega < 1.0) ++r.outliers;
  add_rows(r.jtwj, r.jtwj, jx, omega * w_xx, jt, omega * w_tt, settings);
  if (w_xt != 0.0) r.jtwj.selfadjointView<Eigen::Upper>().rankUpdate(jx, jt, omega * w_xt);
  const Eigen::Vector2d e = w * Eigen::Vector2d(rx, rt);  // W r
  WeightedSample out;
  out.score = omega * (e[0] * jx + e[1] * jt);
  out.omega = omega;
  out.gt = g[1];
  r.cost += omega * (rx * e[0] + rt * e[1]) - (wx * rx * rx + wt * rt * rt);
  // Fisher scoring on v = (σx², σT̄², s): D_x = e₁e₁ᵀ, D_T = e₂e₂ᵀ, D_s = g gᵀ + P/s (the
  // landing filter's P is proportional to s: its only source is the landings' jitter).
  const Eigen::Matrix2d d_s =
      g * g.transpose() + (s > 0.0 ? (pred / s).eval() : Eigen::Matrix2d::Zero().eval());
  const Eigen::Matrix2d wdw = w * d_s * w;
  // The variances' score with the quadratic terms weighted ω²/κ (Huber's proposal 2): a
  // down-weighted sample adds at most threshold² however far its stamp was displaced, and
  // κ = E[min(m², a²)]/2 = 1 − e^{−a²/2} for a Gaussian two-channel residual keeps the estimate
  // unbiased on clean data.
  const double q2 = omega * omega / outlier_consistency(settings.outlier_threshold);
  r.variance_score += 0.5 * Eigen::Vector3d(q2 * e[0] * e[0] - w_xx, q2 * e[1] * e[1] - w_tt,
                                            q2 * e.dot(d_s * e) - (w * d_s).trace());
  Eigen::Matrix3d info;
  info << w_xx * w_xx, w_xt * w_xt, wdw(0, 0),  //
      w_xt * w_xt, w_tt * w_tt, wdw(1, 1),      //
      wdw(0, 0), wdw(1, 1), (wdw * d_s).trace();
  r.variance_information += 0.5 * info;
  r.speed_squares[0] += g[0] * g[0];
  r.speed_squares[1] += g[1] * g[1];
  return out;
}

// PassSettings::landing_jitter: the landing filter's update at a sample, after its sensitivities
// were used: a down-weighted sample (a displaced stamp) corrects the state as much less as it
// counts. The reference trajectory is filtered alike, so that its residuals, which set the robust
// weights, are innovations too. `jt`: the T̄ reading's sensitivity (the innovation's, negated).
void update_with_landing(const PassSettings& settings, double wt, const WeightedSample& sample,
                         const WindowSample& w, double t0, double rt, const ParamVector& jt,
                         Reference& ref, SensitivitySimulator& sim) {
  const Eigen::Vector3d gain = ref.filter.update_with_tbar(
      1.0 / wt + settings.timing_variance * sample.gt * sample.gt, sample.omega);
  sim.correct_with_tbar(gain, rt, jt);
  correct_with_tbar(ref.state, gain, ref.tbar_residual(w, settings, t0));
}

// With sensitivities: JᵀWJ, JᵀWr and, as PassSettings asks, the long-run covariance of the score,
// its batch sums, the timing weights and the landing filter. Returns whether it gave up.
bool jacobian_pass(std::span<const WindowSample> window, const ParamVector& p,
                   const PassSettings& settings, ResidualSums& sums) {
  PassResult& r = sums.r;
  const double wx = sums.wx, wt = sums.wt;
  SensitivitySimulator sim(theta_of(p), initial_state_of(p), settings.thermal_only, tempcos_of(p),
                           settings.extensions);
  const bool timing = settings.timing && !settings.thermal_only;
  // PassSettings::landing_jitter: the Kalman filter on [x, ẋ, T̄] (refine/landing_filter.hpp).
  Reference ref(settings, timing && settings.landing_jitter && wt > 0.0);
  std::unique_ptr<LongRunAccumulator> hac;
  if (settings.hac_bandwidth > 0)
    hac = std::make_unique<LongRunAccumulator>(settings.hac_bandwidth,
                                               settings.extensions || settings.sensor_lag);
  BatchSums batch_sums(settings.batches, window.size());
  std::size_t next_batch = batch_sums.next_start();
  ParamVector* batch_score = nullptr;
  // The sensor's lag: applied where it is not 0 or is estimated (its sensitivity at 0 is −dT̄/dt).
  SensorLag lag(p[kSensorLagSlot]);
  const bool lagged = p[kSensorLagSlot] != 0.0 || settings.sensor_lag;
  lag.start(sim.state().tbar, &sim.dtbar());
  ChannelSums channels;  // without the timing weights, each channel's share apart
  double rx = 0.0, rt = 0.0;
  bool stopped = false;
  for (std::size_t k = 0; k < window.size(); ++k) {
    if (k > 0) sim.advance(window[k - 1], window[k], settings.input_delay);
    if (timing && k > 0) ref.advance(window[k - 1], window[k], settings);
    if (give_up(settings, k, sim.substeps_taken(), sim.state(), r)) {
      stopped = true;
      break;
    }
    if (lagged && k > 0) lag.advance(window[k].t - window[k - 1].t, sim.state().tbar, &sim.dtbar());
    sums.add(k, window[k], sim.state(), lagged ? lag.reading() : sim.state().tbar, rx, rt);
    ParamVector jx = sim.dx(), jt = lagged ? lag.sensitivities() : sim.dtbar();
    // The outputs' own terms, on top of what the landing filter's corrections carried into the
    // state (update_with_landing).
    jx[kXZeroSlot] += 1.0;
    jt[kAmbientOffsetSlot] += 1.0;
    jt[kAmbientDriftSlot] += window[k].t - sums.t0;
    if (settings.validator != nullptr)
      feed_validator(*settings.validator, window, k, sim, jx, jt, rx, rt, settings.input_delay);
    if (k == next_batch) [[unlikely]] {
      // sums.add has counted sample k's wx·rx² + wt·rt² already.
      const ParamMatrix so_far = timing ? r.jtwj : (channels.jtwj[0] + channels.jtwj[1]).eval();
      batch_score = batch_sums.begin_batch(k, so_far, r.cost - (wx * rx * rx + wt * rt * rt));
      next_batch = batch_sums.next_start();
    }
    WeightedSample sample;
    if (!timing) {
      add_rows(channels.jtwj[0], channels.jtwj[1], jx, wx, jt, wt, settings);
      const ParamVector sx = wx * rx * jx, st = wt * rt * jt;
      channels.jtwr[0] += sx;
      channels.jtwr[1] += st;
      sample.score = sx + st;
    } else {
      sample = add_timing_weighted(settings, wx, wt, ref, window[k], sums.t0, rx, rt, jx, jt, r);
    }
    if (ref.landing)
      update_with_landing(settings, wt, sample, window[k], sums.t0, rt, jt, ref, sim);
    r.jtwr += sample.score;
    if (hac) hac->add(sample.score);
    if (batch_score != nullptr) *batch_score += sample.score;
  }
  if (!timing) {
    for (ParamMatrix& h : channels.jtwj) h = h.selfadjointView<Eigen::Upper>();
    r.jtwj = channels.jtwj[0] + channels.jtwj[1];
    r.channels = channels;
  }
  batch_sums.finish(r.jtwj, r.cost);
  batch_sums.move_into(r);
  r.jtwj = r.jtwj.selfadjointView<Eigen::Upper>();
  if (hac) r.long_run = hac->result();
  r.substeps = sim.substeps_taken();
  return stopped;
}

}  // namespace

PassResult residual_pass(std::span<const WindowSample> window, const ParamVector& p,
                         const PassSettings& settings) {
  PassResult r;
  if (window.empty()) return r;
  const double wx = settings.thermal_only ? 0.0 : settings.weight[0];
  const double wt = settings.weight[1];
  ResidualSums sums{r, wx, wt, p, window.front().t};
  r.tbar_min = r.tbar_max = initial_state_of(p)[2];
  const bool stopped = settings.jacobian ? jacobian_pass(window, p, settings, sums)
                                         : cost_only_pass(window, p, settings, sums);
  r.finite = !stopped && std::isfinite(r.cost) && r.jtwj.allFinite() && r.jtwr.allFinite();
  return r;
}

std::optional<PassResult> reweighted(const PassResult& pass, const std::array<double, 2>& from,
                                     const std::array<double, 2>& to) {
  if (!pass.finite || !pass.channels) return std::nullopt;
  PassResult out;
  out.finite = true;
  out.rss = pass.rss;
  out.lag1 = pass.lag1;
  out.tbar_min = pass.tbar_min;
  out.tbar_max = pass.tbar_max;
  out.substeps = pass.substeps;
  ChannelSums channels;
  for (std::size_t c = 0; c < 2; ++c) {
    if (from[c] == 0.0) {
      // A channel the pass left out cannot be weighted in.
      if (to[c] != 0.0) return std::nullopt;
      continue;
    }
    const double scale = to[c] / from[c];
    channels.jtwj[c] = scale * pass.channels->jtwj[c];
    channels.jtwr[c] = scale * pass.channels->jtwr[c];
    out.cost += to[c] * pass.rss[c];
  }
  out.jtwj = channels.jtwj[0] + channels.jtwj[1];
  out.jtwr = channels.jtwr[0] + channels.jtwr[1];
  out.channels = channels;
  if (!std::isfinite(out.cost) || !out.jtwj.allFinite() || !out.jtwr.allFinite())
    return std::nullopt;
  return out;
}

}  // namespace scp::refine

#include "refine/switch_placement.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <memory>
#include <vector>

#include "refine/fitted_sweep.hpp"
#include "refine/model_simulator.hpp"

namespace scp::refine {

namespace {

using SwitchMatrix = Eigen::Matrix<double, Eigen::Dynamic, kParams>;

// A switch row and what moving its switch does to the model.
struct Switch {
  std::size_t row = 0;
  double phase = 0.0;  // where it is now: 0 at the previous sample, 1 at the row
  double heat = 0.0;  // T̄'s change per unit of phase later: θ6·(A² − B²)·Δ at the local heating
};

// The model linearised about the fit's trajectory, per sample k (the interval (t_{k−1}, t_k]): a
// perturbation D of T̄ decays by `decay`, the sensor's reading y follows it (y_k = lag·y_{k−1} +
// (1 − lag)·D_k), and x moves by `x_gain`·D (the mechanical block's static response).
struct LinearModel {
  std::vector<double> decay, lag, x_gain;
  double wx = 0.0, wt = 0.0;  // the channels' weights, 1/σ²
};

// What one sweep of the fitted model gives: the linear model, the weighted residuals, the
// switches, and the information of the phases and the fit's slots: HᵢᵀWHᵢ (diagonal),
// HᵀWJ (cross) and JᵀWJ, JᵀWr (slots).
struct Sweep {
  LinearModel model;
  std::vector<double> wrt, wrx;  // W r per sample, T̄ and x
  std::vector<Switch> switches;
  Eigen::VectorXd diagonal;
  SwitchMatrix cross;
  ParamMatrix slots = ParamMatrix::Zero();
  ParamVector slots_score = ParamVector::Zero();
};

// ∂x/∂T̄ at rest in the mechanical block m ẍ + (b + α1 T̄) ẋ + k(1 − κT̄) x = −α2 T̄, about the
// trajectory's x and ẋ.
double static_x_gain(const Vector6& theta, const Tempcos& tc, const ModelState& s) {
  const double stiffness = theta[kStiffness] * (1.0 - tc.kappa * s.tbar);
  if (!(std::abs(stiffness) > 0.0)) return 0.0;
  return -(theta[kThermalForce] + theta[kDampingSlope] * s.xdot -
           theta[kStiffness] * tc.kappa * s.x) /
         stiffness;
}

// The switches' columns while they last: each one's perturbation D and reading y, carried from
// its row until both have decayed below kColumnEnd of its first step.
class ActiveColumns {
 public:
  void start(std::size_t index, double heat) { active_.push_back({index, heat, 0.0, 0.0}); }

  // Advances every column to sample k and adds its products with the sensitivities.
  void advance(const LinearModel& m, std::size_t k, const ParamVector& jx, const ParamVector& jt,
               std::span<const Switch> switches, Eigen::VectorXd& diagonal, SwitchMatrix& cross) {
    std::size_t kept = 0;
    for (Column& c : active_) {
      const bool first = switches[c.index].row == k;
      c.d = first ? c.heat : m.decay[k] * c.d;
      c.y = m.lag[k] * c.y + (1.0 - m.lag[k]) * c.d;
      const double x = m.x_gain[k] * c.d;
      diagonal[static_cast<Eigen::Index>(c.index)] += m.wt * c.y * c.y + m.wx * x * x;
      cross.row(static_cast<Eigen::Index>(c.index)) +=
          (m.wt * c.y * jt + m.wx * x * jx).transpose();
      const double end = kColumnEnd * std::abs(c.heat);
      if (first || std::abs(c.d) > end || std::abs(c.y) > end) active_[kept++] = c;
    }
    active_.resize(kept);
  }

 private:
  // A column's share of the sums once both are below this: a millionth of its first step, whose
  // square is its share of the column's information per sample.
  static constexpr double kColumnEnd = 1e-6;
  struct Column {
    std::size_t index;
    double heat, d, y;
  };
  std::vector<Column> active_;
};

// The rows a foh window holds (hold_voltage_switches' switches), at their phases; heat unset.
std::vector<Switch> switch_rows(std::span<const WindowSample> w) {
  std::vector<Switch> out;
  for (std::size_t k = 1; k < w.size(); ++k) {
    const double dt = w[k].t - w[k - 1].t;
    if (w[k].voltage_ramp || !(dt > 0.0)) continue;
    out.push_back({k, std::clamp((w[k].voltage_since - w[k - 1].t) / dt, 0.0, 1.0), 0.0});
  }
  return out;
}

// A linear model of n samples that passes a perturbation on unchanged, the channels weighted by
// the noise σ (x, T̄).
LinearModel unit_model(std::size_t n, const Vector2& noise_sigma) {
  LinearModel m;
  m.decay.assign(n, 1.0);
  m.lag.assign(n, 0.0);
  m.x_gain.assign(n, 0.0);
  m.wx = 1.0 / (noise_sigma[0] * noise_sigma[0]);
  m.wt = 1.0 / (noise_sigma[1] * noise_sigma[1]);
  return m;
}

Sweep sweep(std::span<const WindowSample> w, const FitResult& fit,
            const std::array<bool, 6>& known) {
  const Tempcos tc = fitted_tempcos(fit);
  const FreeMask free = fitted_slots(fit, known);
  const double sensor_lag = fit.nuisance.sensor_lag.value;
  Sweep out;
  LinearModel& m = out.model;
  m = unit_model(w.size(), fit.noise_sigma);
  out.wrt.assign(w.size(), 0.0);
  out.wrx.assign(w.size(), 0.0);
  out.switches = switch_rows(w);
  out.diagonal = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(out.switches.size()));
  out.cross = SwitchMatrix::Zero(static_cast<Eigen::Index>(out.switches.size()), kParams);
  if (out.switches.empty() || out.switches.size() > kMostPlacedSwitches) return out;
  ActiveColumns columns;
  std::size_t next = 0;
  double prev_tbar = fit.initial_state[2];
  sweep_fitted_model(w, fit, [&](const FittedSample& f) {
    const std::size_t k = f.k;
    const ModelState& s = *f.state;
    m.x_gain[k] = static_x_gain(fit.theta, tc, s);
    if (k > 0) {
      const double dt = w[k].t - w[k - 1].t;
      const ThermalLinearization l = linearize_thermal(fit.theta, tc, prev_tbar, f.thermal_input);
      m.decay[k] = std::exp(-l.a * dt);
      m.lag[k] = sensor_lag > 0.0 ? std::exp(-dt / sensor_lag) : 0.0;
      if (next < out.switches.size() && out.switches[next].row == k) {
        const double before = w[k - 1].voltage * w[k - 1].voltage;
        const double after = w[k].voltage * w[k].voltage;
        out.switches[next].heat = l.b * (before - after) * dt;
        columns.start(next, out.switches[next].heat);
        ++next;
      }
    }
    prev_tbar = s.tbar;
    const double rx = w[k].x - f.x_model, rt = w[k].tbar - f.tbar_model;
    out.wrx[k] = m.wx * rx;
    out.wrt[k] = m.wt * rt;
    ParamVector jx = *f.jx, jt = *f.jt;
    for (int i = 0; i < kParams; ++i) {
      if (free[static_cast<std::size_t>(i)]) continue;
      jx[i] = 0.0;
      jt[i] = 0.0;
    }
    out.slots.selfadjointView<Eigen::Upper>().rankUpdate(jx, m.wx);
    out.slots.selfadjointView<Eigen::Upper>().rankUpdate(jt, m.wt);
    out.slots_score += out.wrx[k] * jx + out.wrt[k] * jt;
    columns.advance(m, k, jx, jt, out.switches, out.diagonal, out.cross);
  });
  out.slots = out.slots.selfadjointView<Eigen::Upper>();
  return out;
}

// Hᵀu for per-sample output weights (ut on T̄'s reading, ux on x): the linear model's adjoint.
Eigen::VectorXd adjoint(const LinearModel& m, std::span<const Switch> switches,
                        const std::vector<double>& ut, const std::vector<double>& ux) {
  const std::size_t n = ut.size();
  std::vector<double> lambda_d(n, 0.0);
  double ly = 0.0, ld = 0.0;  // the adjoints of y and D at k + 1
  for (std::size_t k = n; k-- > 0;) {
    const bool last = k + 1 == n;
    // y_{k+1} = lag·y_k + (1 − lag)·D_{k+1} and D_{k+1} = decay·D_k + impulse: D_k reaches the
    // outputs through its own reading and x, and through D_{k+1} (whose adjoint holds the rest).
    ly = ut[k] + (last ? 0.0 : m.lag[k + 1] * ly);
    ld = ux[k] * m.x_gain[k] + (1.0 - m.lag[k]) * ly + (last ? 0.0 : m.decay[k + 1] * ld);
    lambda_d[k] = ld;
  }
  Eigen::VectorXd g(static_cast<Eigen::Index>(switches.size()));
  for (std::size_t i = 0; i < switches.size(); ++i)
    g[static_cast<Eigen::Index>(i)] = switches[i].heat * lambda_d[switches[i].row];
  return g;
}

// The phases' normal matrix with the fit's slots profiled out, applied to δ:
// (HᵀWH + prior)·δ − C·A⁻¹·Cᵀδ, C = HᵀWJ, A = JᵀWJ over the free slots.
class ProfiledNormal {
 public:
  ProfiledNormal(const Sweep& s, std::size_t samples)
      : s_(s), ut_(samples), ux_(samples), impulse_(samples, 0.0) {
    const Eigen::VectorXd scale = s.slots.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
    const ParamMatrix scaled = scale.asDiagonal() * s.slots * scale.asDiagonal();
    ParamMatrix regular = scaled;
    // Held slots have zero columns: a unit diagonal keeps them out of the solve.
    for (int i = 0; i < kParams; ++i)
      if (!(s.slots(i, i) > 0.0)) regular(i, i) = 1.0;
    scale_ = scale;
    solver_.compute(regular);
  }

  bool ok() const { return solver_.info() == Eigen::Success; }

  // A⁻¹·v over the free slots (0 on the held ones).
  ParamVector slots_solve(const ParamVector& v) const {
    const ParamVector scaled = scale_.cwiseProduct(v);
    return scale_.cwiseProduct(solver_.solve(scaled));
  }

  Eigen::VectorXd apply(const Eigen::VectorXd& delta) {
    std::fill(impulse_.begin(), impulse_.end(), 0.0);
    for (std::size_t i = 0; i < s_.switches.size(); ++i)
      impulse_[s_.switches[i].row] += s_.switches[i].heat * delta[static_cast<Eigen::Index>(i)];
    const LinearModel& m = s_.model;
    double d = 0.0, y = 0.0;
    for (std::size_t k = 0; k < impulse_.size(); ++k) {
      d = m.decay[k] * d + impulse_[k];
      y = m.lag[k] * y + (1.0 - m.lag[k]) * d;
      ut_[k] = m.wt * y;
      ux_[k] = m.wx * m.x_gain[k] * d;
    }
    const ParamVector cross_t = s_.cross.transpose() * delta;
    return adjoint(m, s_.switches, ut_, ux_) + kSwitchPhasePriorPrecision * delta -
           s_.cross * slots_solve(cross_t);
  }

  // The diagonal of the profiled matrix, for the preconditioner.
  Eigen::VectorXd diagonal() const {
    Eigen::VectorXd out = s_.diagonal.array() + kSwitchPhasePriorPrecision;
    for (Eigen::Index i = 0; i < out.size(); ++i) {
      const ParamVector c = s_.cross.row(i).transpose();
      out[i] = std::max(out[i] - c.dot(slots_solve(c)), kSwitchPhasePriorPrecision);
    }
    return out;
  }

 private:
  const Sweep& s_;
  std::vector<double> ut_, ux_, impulse_;
  ParamVector scale_ = ParamVector::Ones();
  Eigen::LDLT<ParamMatrix> solver_;
};

// Solves M·δ = b by conjugate gradients preconditioned by M's diagonal.
Eigen::VectorXd conjugate_gradients(ProfiledNormal& op, const Eigen::VectorXd& b,
                                    const Eigen::VectorXd& diagonal) {
  constexpr int kMaxIterations = 500;
  constexpr double kTolerance = 1e-8;  // of the residual's norm, relative to b's
  Eigen::VectorXd x = Eigen::VectorXd::Zero(b.size());
  Eigen::VectorXd r = b;
  Eigen::VectorXd z = r.cwiseQuotient(diagonal);
  Eigen::VectorXd d = z;
  double rz = r.dot(z);
  const double stop = kTolerance * kTolerance * b.squaredNorm();
  for (int it = 0; it < kMaxIterations && r.squaredNorm() > stop; ++it) {
    const Eigen::VectorXd q = op.apply(d);
    const double dq = d.dot(q);
    if (!(dq > 0.0)) break;
    const double alpha = rz / dq;
    x += alpha * d;
    r -= alpha * q;
    z = r.cwiseQuotient(diagonal);
    const double rz_next = r.dot(z);
    d = z + (rz_next / rz) * d;
    rz = rz_next;
  }
  return x;
}

// The sweep, the profiled operator and its preconditioner of one placement, or nothing.
struct Placement {
  Sweep sweep;
  std::unique_ptr<ProfiledNormal> op;
  Eigen::VectorXd diagonal;
};

bool prepare_placement(std::span<const WindowSample> prepared, const FitResult& fit,
                       const std::array<bool, 6>& known, Placement& out) {
  if (prepared.size() < 3 || !(fit.noise_sigma.array() > 0.0).all()) return false;
  out.sweep = sweep(prepared, fit, known);
  const Sweep& s = out.sweep;
  if (s.switches.empty() || s.switches.size() > kMostPlacedSwitches) return false;
  if (!s.cross.allFinite() || !s.slots.allFinite() || !s.diagonal.allFinite()) return false;
  out.op = std::make_unique<ProfiledNormal>(s, prepared.size());
  if (!out.op->ok()) return false;
  out.diagonal = out.op->diagonal();
  return true;
}

}  // namespace

Matrix6 placed_switches_covariance(std::span<const WindowSample> prepared, const FitResult& fit,
                                   const std::array<bool, 6>& known) {
  Placement p;
  if (!prepare_placement(prepared, fit, known, p)) return Matrix6::Zero();
  // G = C A⁻¹ over θ's columns; the share is Gᵀ S⁻¹ G.
  Eigen::Matrix<double, Eigen::Dynamic, 6> g(p.sweep.cross.rows(), 6);
  for (int j = 0; j < 6; ++j) g.col(j) = p.sweep.cross * p.op->slots_solve(ParamVector::Unit(j));
  Eigen::Matrix<double, Eigen::Dynamic, 6> solved(g.rows(), 6);
  for (int j = 0; j < 6; ++j) solved.col(j) = conjugate_gradients(*p.op, g.col(j), p.diagonal);
  Matrix6 share = g.transpose() * solved;
  share = 0.5 * (share + share.transpose()).eval();
  if (!share.allFinite()) return Matrix6::Zero();
  return share;
}

SwitchPlacement place_voltage_switches(std::span<WindowSample> prepared, const FitResult& fit,
                                       const std::array<bool, 6>& known, PlacementStep step) {
  SwitchPlacement out;
  Placement p;
  if (!prepare_placement(prepared, fit, known, p)) return out;
  const Sweep& s = p.sweep;
  const Eigen::VectorXd& diagonal = p.diagonal;
  // The score of the phases with the slots' own score profiled out (0 at a converged fit).
  const Eigen::VectorXd b =
      adjoint(s.model, s.switches, s.wrt, s.wrx) - s.cross * p.op->slots_solve(s.slots_score);
  const Eigen::VectorXd delta = conjugate_gradients(*p.op, b, diagonal);
  if (!delta.allFinite()) return out;
  out.decrease = b.dot(delta);
  out.price =
      static_cast<double>(s.switches.size()) * std::log(static_cast<double>(prepared.size()));
  if (step == PlacementStep::needs_evidence && !(out.decrease > out.price)) return out;
  double variance = 0.0;
  for (std::size_t i = 0; i < s.switches.size(); ++i) {
    const Switch& sw = s.switches[i];
    const auto at = static_cast<Eigen::Index>(i);
    const double phase = std::clamp(sw.phase + delta[at], 0.0, 1.0);
    const WindowSample& prev = prepared[sw.row - 1];
    prepared[sw.row].voltage_since = prev.t + phase * (prepared[sw.row].t - prev.t);
    out.largest_move = std::max(out.largest_move, std::abs(phase - sw.phase));
    variance += 1.0 / diagonal[at];
  }
  out.placed = s.switches.size();
  out.rms_phase_sigma = std::sqrt(variance / static_cast<double>(s.switches.size()));
  return out;
}

}  // namespace scp::refine

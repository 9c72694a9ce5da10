#include "refine/switch_placement.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <vector>

#include "refine/fitted_sweep.hpp"
#include "refine/model_simulator.hpp"
#include "refine/outer_update.hpp"
#include "refine/switch_perturbation.hpp"
#include "refine/validate_fit.hpp"

namespace scp::refine {

namespace {

using switch_model::kReading;
using switch_model::kX;
using switch_model::OutputRow;
using switch_model::Outputs;
using switch_model::Perturbation;
using switch_model::PerturbationMap;
using switch_model::PerturbationSteps;
using switch_model::Switch;
using switch_model::switch_rows;

using SwitchMatrix = Eigen::Matrix<double, Eigen::Dynamic, kParams>;
// The model linearised about the fit's trajectory, per sample k (the interval (t_{k−1}, t_k]): a
// perturbation D of T̄ decays by `decay`, the sensor's reading y follows it (y_k = lag·y_{k−1} +
// (1 − lag)·D_k), and x's (δx, δẋ) follow the mechanical block linearised about the trajectory,
// driven by D. So the perturbation at k is a fixed 4×4 image of it at any earlier k, and what it
// does over the stretch between two switch rows is linear in the state it enters the stretch
// with: one sweep sums each stretch for a unit start, and the switches are then carried over the
// stretches.
struct Stretch {
  Eigen::Matrix<double, kParams, 4> cross = Eigen::Matrix<double, kParams, 4>::Zero();  // JᵀW·O
  PerturbationMap quadratic = PerturbationMap::Zero();                                  // OᵀW·O
  Perturbation residual = Perturbation::Zero();                                         // OᵀW·r
  PerturbationMap onward = PerturbationMap::Zero();  // the perturbation at the next switch row
};

// What one sweep of the fitted model gives: the switches, the stretches from each switch row to
// the next (the last to the window's end), and from them the information of the phases and the
// fit's slots: HᵢᵀWHᵢ (diagonal), HᵀWJ (cross), HᵀWr (score), JᵀWJ and JᵀWr (slots).
struct Sweep {
  std::vector<Switch> switches;
  std::vector<Stretch> stretches;
  Eigen::VectorXd diagonal, score;
  SwitchMatrix cross;
  ParamMatrix slots = ParamMatrix::Zero();
  ParamVector slots_score = ParamVector::Zero();
};

// Sums the stretches during the sweep: psi_ is the perturbation at the current sample per unit
// start of the current stretch.
class StretchSums {
 public:
  explicit StretchSums(std::vector<Stretch>& out) : out_(out) {}

  // Sample k's step; `switch_row`: a switch starts at k (its own stretch, from k's sample on).
  void step(const PerturbationMap& step, bool switch_row) {
    if (!switch_row) {
      psi_ = step * psi_;
      return;
    }
    if (!out_.empty()) out_.back().onward = step * psi_;
    out_.emplace_back();
    psi_.setIdentity();
  }

  // Sample k's outputs per unit start: δx and T̄'s reading y, weighted wx, wt.
  void add(double wx, double wt, const ParamVector& jx, const ParamVector& jt, double wrx,
           double wrt) {
    if (out_.empty()) return;
    Stretch& s = out_.back();
    const OutputRow ox = psi_.row(kX), oy = psi_.row(kReading);
    s.cross.noalias() += (wx * jx) * ox + (wt * jt) * oy;
    s.quadratic.noalias() += wx * ox.transpose() * ox + wt * oy.transpose() * oy;
    s.residual.noalias() += wrx * ox.transpose() + wrt * oy.transpose();
  }

 private:
  std::vector<Stretch>& out_;
  PerturbationMap psi_ = PerturbationMap::Identity();
};

// Each switch's columns, carried back from the window's end over the stretches: C_j = S_j +
// C_{j+1}·T_j, Q_j = R_j + T_jᵀ·Q_{j+1}·T_j, g_j = ρ_j + T_jᵀ·g_{j+1} (T_j: onward).
void switch_columns(Sweep& s) {
  const auto n = static_cast<Eigen::Index>(s.switches.size());
  s.diagonal = Eigen::VectorXd::Zero(n);
  s.score = Eigen::VectorXd::Zero(n);
  s.cross = SwitchMatrix::Zero(n, kParams);
  Eigen::Matrix<double, kParams, 4> c = Eigen::Matrix<double, kParams, 4>::Zero();
  PerturbationMap q = PerturbationMap::Zero();
  Perturbation g = Perturbation::Zero();
  for (std::size_t j = s.stretches.size(); j-- > 0;) {
    const Stretch& st = s.stretches[j];
    c = st.cross + c * st.onward;
    q = st.quadratic + st.onward.transpose() * q * st.onward;
    g = st.residual + st.onward.transpose() * g;
    const Perturbation& start = s.switches[j].start;
    const auto at = static_cast<Eigen::Index>(j);
    s.cross.row(at) = (c * start).transpose();
    s.diagonal[at] = start.dot(q * start);
    s.score[at] = start.dot(g);
  }
}

// JᵀWJ's upper triangle += wx·jx·jxᵀ + wt·jt·jtᵀ, term by term as Eigen's rank updates of it
// would (the same sums), unrolled over the slots each row can touch: those rank updates' loops
// over run-time lengths cost as much as the rest of the sweep. The sweep's end copies the upper
// half to the lower.
void add_weighted_outer(ParamMatrix& slots, const ParamVector& jx, double wx, const ParamVector& jt,
                        double wt) {
  outer_update::add_outer_upper<outer_update::kXRowSlotsExtended>(slots, jx, wx);
  outer_update::add_outer_upper<outer_update::kTbarRowSlotsExtended>(slots, jt, wt);
}

Sweep sweep(std::span<const WindowSample> w, const FitResult& fit,
            const std::array<bool, 6>& known) {
  const FreeMask free = fitted_slots(fit, known);
  const double wx = 1.0 / (fit.noise_sigma[0] * fit.noise_sigma[0]);
  const double wt = 1.0 / (fit.noise_sigma[1] * fit.noise_sigma[1]);
  Sweep out;
  out.switches = switch_rows(w);
  if (out.switches.empty() || out.switches.size() > kMostPlacedSwitches) return out;
  out.stretches.reserve(out.switches.size());
  StretchSums sums(out.stretches);
  std::size_t next = 0;
  PerturbationSteps steps(fit, Outputs::both);
  sweep_fitted_model(w, fit, [&](const FittedSample& f) {
    const std::size_t k = f.k;
    const ModelState& s = *f.state;
    if (k > 0) {
      const bool switch_row = next < out.switches.size() && out.switches[next].row == k;
      sums.step(
          steps.step(w, k, f.thermal_input, switch_row ? &out.switches[next++].start : nullptr),
          switch_row);
    }
    steps.passed(s);
    ParamVector jx = *f.jx, jt = *f.jt;
    for (int i = 0; i < kParams; ++i) {
      if (free[static_cast<std::size_t>(i)]) continue;
      jx[i] = 0.0;
      jt[i] = 0.0;
    }
    const double wrx = wx * (w[k].x - f.x_model), wrt = wt * (w[k].tbar - f.tbar_model);
    add_weighted_outer(out.slots, jx, wx, jt, wt);
    out.slots_score += wrx * jx + wrt * jt;
    sums.add(wx, wt, jx, jt, wrx, wrt);
  });
  out.slots = out.slots.selfadjointView<Eigen::Upper>();
  if (out.stretches.size() == out.switches.size()) switch_columns(out);
  return out;
}

// The phases' normal matrix with the fit's slots profiled out, applied to δ:
// (HᵀWH + prior)·δ − C·A⁻¹·Cᵀδ, C = HᵀWJ, A = JᵀWJ over the free slots.
class ProfiledNormal {
 public:
  explicit ProfiledNormal(const Sweep& s) : s_(s), entering_(s.stretches.size()) {
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

  // HᵀWH·δ: forward, the perturbation z_j every stretch starts with (z_j = T_{j−1}·z_{j−1} +
  // start_j·δ_j); backward, a_j = R_j·z_j + T_jᵀ·a_{j+1}, and (HᵀWHδ)_j = start_j·a_j.
  Eigen::VectorXd apply(const Eigen::VectorXd& delta) {
    const std::vector<Stretch>& st = s_.stretches;
    Perturbation z = Perturbation::Zero();
    for (std::size_t j = 0; j < st.size(); ++j) {
      if (j > 0) z = st[j - 1].onward * z;
      z += s_.switches[j].start * delta[static_cast<Eigen::Index>(j)];
      entering_[j] = z;
    }
    Eigen::VectorXd out(delta.size());
    Perturbation a = Perturbation::Zero();
    for (std::size_t j = st.size(); j-- > 0;) {
      a = st[j].quadratic * entering_[j] + st[j].onward.transpose() * a;
      out[static_cast<Eigen::Index>(j)] = s_.switches[j].start.dot(a);
    }
    const ParamVector cross_t = s_.cross.transpose() * delta;
    return out + kSwitchPhasePriorPrecision * delta - s_.cross * slots_solve(cross_t);
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
  std::vector<Perturbation> entering_;
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
  if (s.stretches.size() != s.switches.size()) return false;  // the sweep stopped short
  if (!s.cross.allFinite() || !s.slots.allFinite() || !s.diagonal.allFinite() ||
      !s.score.allFinite()) {
    return false;
  }
  out.op = std::make_unique<ProfiledNormal>(s);
  if (!out.op->ok()) return false;
  out.diagonal = out.op->diagonal();
  return true;
}

// Gauss–Newton's step for the phases with the slots profiled out, each phase kept inside its
// interval, and the weighted cost that step takes off in the linear model (2bᵀδ − δᵀMδ: bᵀδ where
// no phase met its interval's end); false where the step is not finite. A switch the data put at
// the edge of its interval would otherwise ask for a step it cannot take at every round, and the
// rounds would not settle.
bool phase_step(Placement& p, Eigen::VectorXd& delta, double& decrease) {
  const Sweep& s = p.sweep;
  // The score of the phases with the slots' own score profiled out (0 at a converged fit).
  const Eigen::VectorXd b = s.score - s.cross * p.op->slots_solve(s.slots_score);
  delta = conjugate_gradients(*p.op, b, p.diagonal);
  if (!delta.allFinite()) return false;
  bool clamped = false;
  for (std::size_t i = 0; i < s.switches.size(); ++i) {
    const auto at = static_cast<Eigen::Index>(i);
    const double phase = s.switches[i].phase;
    const double inside = std::clamp(phase + delta[at], 0.0, 1.0) - phase;
    clamped |= inside != delta[at];
    delta[at] = inside;
  }
  decrease = clamped ? 2.0 * b.dot(delta) - delta.dot(p.op->apply(delta)) : b.dot(delta);
  return std::isfinite(decrease);
}

// placed_switches_covariance's share from a placement's sweep.
Matrix6 covariance_share(Placement& p) {
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

}  // namespace

Matrix6 placed_switches_covariance(std::span<const WindowSample> prepared, const FitResult& fit,
                                   const std::array<bool, 6>& known) {
  Placement p;
  if (!prepare_placement(prepared, fit, known, p)) return Matrix6::Zero();
  return covariance_share(p);
}

double placement_decrease(std::span<const WindowSample> prepared, const FitResult& fit,
                          const std::array<bool, 6>& known) {
  Placement p;
  if (!prepare_placement(prepared, fit, known, p)) return 0.0;
  Eigen::VectorXd delta;
  double decrease = 0.0;
  return phase_step(p, delta, decrease) ? std::max(decrease, 0.0) : 0.0;
}

SwitchPlacement place_voltage_switches(std::span<WindowSample> prepared, const FitResult& fit,
                                       const std::array<bool, 6>& known, PlacementStep step,
                                       double settled_decrease) {
  SwitchPlacement out;
  Placement p;
  if (!prepare_placement(prepared, fit, known, p)) return out;
  const Sweep& s = p.sweep;
  const Eigen::VectorXd& diagonal = p.diagonal;
  Eigen::VectorXd delta;
  if (!phase_step(p, delta, out.decrease)) return out;
  out.price =
      static_cast<double>(s.switches.size()) * std::log(static_cast<double>(prepared.size()));
  if (step == PlacementStep::needs_evidence && !(out.decrease > out.price)) return out;
  out.settled = settled_decrease > 0.0 && !(out.decrease >= settled_decrease);
  double variance = 0.0;
  for (std::size_t i = 0; i < s.switches.size(); ++i) {
    const auto at = static_cast<Eigen::Index>(i);
    variance += 1.0 / diagonal[at];
    if (out.settled) continue;
    const Switch& sw = s.switches[i];
    const double phase = std::clamp(sw.phase + delta[at], 0.0, 1.0);
    const WindowSample& prev = prepared[sw.row - 1];
    prepared[sw.row].voltage_since = prev.t + phase * (prepared[sw.row].t - prev.t);
    out.largest_move = std::max(out.largest_move, std::abs(phase - sw.phase));
  }
  out.placed = s.switches.size();
  out.rms_phase_sigma = std::sqrt(variance / static_cast<double>(s.switches.size()));
  if (out.settled) out.covariance_share = covariance_share(p);
  return out;
}

std::vector<PlacedSwitch> placed_switches(std::span<const WindowSample> prepared) {
  std::vector<PlacedSwitch> out;
  for (const Switch& sw : switch_rows(prepared))
    out.push_back({prepared[sw.row].t, prepared[sw.row].voltage_since});
  return out;
}

std::size_t restore_placed_switches(std::span<WindowSample> prepared,
                                    std::span<const PlacedSwitch> placed) {
  std::size_t moved = 0;
  auto next = placed.begin();
  for (const Switch& sw : switch_rows(prepared)) {
    WindowSample& row = prepared[sw.row];
    while (next != placed.end() && next->t < row.t) ++next;
    if (next == placed.end()) break;
    // The same recorded sample: its t is the same double in both windows.
    if (next->t != row.t) continue;
    const double earliest = prepared[sw.row - 1].t;
    if (!(next->since >= earliest && next->since <= row.t)) continue;
    row.voltage_since = next->since;
    ++moved;
  }
  return moved;
}

}  // namespace scp::refine

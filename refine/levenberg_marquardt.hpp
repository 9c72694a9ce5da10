#pragma once
// Levenberg–Marquardt on streamed normal equations (refine/residual_pass.hpp): each evaluation
// returns the cost Σ w r², N = JᵀWJ and g = JᵀWr for the coordinates z being fitted, so the
// solver never sees a residual vector or a Jacobian. Marquardt's diagonal scaling (N + μ·diag N)
// makes the step independent of the parameters' units (θ spans 0.06 to 1813, x0 is 1e-3 m), and
// the linear solve is done on the Jacobi-scaled matrix to keep its condition number down.
//
// Why not Eigen's unsupported LevenbergMarquardt (MINPACK lmder) or Ceres: both want the
// residual vector and its Jacobian (or per-residual blocks), a 2N × kParams matrix for a window
// of N samples, where this solver works in kParams × kParams matrices and reaches the same θ̂ in
// less time (bench/bench_refine.cpp, BM_EigenLevenbergMarquardt; the figures in
// docs/numerics.md, "Figures behind the code comments"). lmder's stopping rules (relative
// ftol/xtol) also know nothing of the noise level, and the per-sample scores the Newey–West
// covariance needs would be one more pass anyway. Eigen's storage-saving lmstr streams Jacobian
// rows but still keeps the 2N residual vector and pays a Givens QR update per row.

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <cmath>
#include <limits>
#include <type_traits>

namespace scp::refine {

// What `evaluate(z)` returns: at least these members (the caller may add its own).
//   bool finite;  double cost;
//   const char* stop;          // non-null: give up now with this message (cancelled, budget spent)
//   Eigen::MatrixXd normal;    // JᵀWJ in z
//   Eigen::VectorXd gradient;  // JᵀWr in z (the cost decreases along +gradient)
// and optionally
//   bool unresolved;  // the model at z has a pole the samples cannot resolve (refine/budget.hpp)
//   bool too_stiff;   // the model at z is too stiff to simulate at all (a failed step)
template <class Evaluation>
struct LmOutcome {
  Eigen::VectorXd z;
  Evaluation at_z;
  int iterations = 0;
  bool converged = false;
  // Ended by the rule of runs_past_resolution(): converged = false.
  bool stalled = false;
  // Ended by the one-step rule (LmSettings::one_step_tolerance): at_z is the start's evaluation
  // with the cost at z.
  bool one_step = false;
  const char* message = "";
};

// Stalled: the run started from a model whose poles the samples resolve, went on to one whose
// fast pole they no longer resolve, and from there the step leads to one too stiff to simulate. The
// cost still falls that way (a term the model lacks, taken up by an ever faster pole), but beyond
// the sampling the data cannot tell those models apart, and each pass there simulates up to
// kMaxPolePerSample / kMaxStiffnessPerSubstep sub-steps per sample: the fit would spend its work
// budget creeping along the bound toward a solution its verdict rejects (fast_pole_unresolved). A
// run that starts beyond the resolution (a scale search's start on the valley) may still come back
// from it.
template <class Evaluation>
bool runs_past_resolution(const Evaluation& start, const Evaluation& current,
                          const Evaluation& trial) {
  if constexpr (requires { current.unresolved, trial.too_stiff; })
    return !start.unresolved && current.unresolved && trial.too_stiff;
  else
    return false;
}

// The damping μ a run starts with, on the Jacobi-scaled normal matrix: small, since that matrix
// has a tiny eigenvalue along the common scale of θ1..θ4 (docs/numerics.md, "A consistent
// estimate") and a μ above it would crush every step along it.
inline constexpr double kInitialDamping = 1e-10;
// Converged when the Gauss–Newton step would lower the cost by less than this fraction of the
// cost per observation: with weights 1/σ², a step below 1e-3 σ of every parameter.
inline constexpr double kDecrementTolerance = 1e-6;

struct LmSettings {
  int max_iterations = 100;
  // 0: the first step is Gauss–Newton's, undamped, for a start already beside the solution (a
  // warm refit); a failed step then moves on from kInitialDamping. Along the common scale even
  // kInitialDamping holds back a step: the scaled eigenvalue there can be below it
  // (docs/numerics.md), and each damped step then leaves a fixed fraction of the way.
  double initial_damping = kInitialDamping;
  double decrement_tolerance = kDecrementTolerance;
  double observations = 1.0;  // weighted observations in the cost (to normalize it)
  // A cost this small is the residual of rounding (noise-free data): converged.
  double cost_floor = 0.0;
  // > 0, with a `cost_at` callback: the first step is taken on one cost-only pass when the cost
  // falls by what the Gauss–Newton model predicted to within this fraction of the cost per
  // observation (levenberg_marquardt()'s one-step rule).
  double one_step_tolerance = 0.0;
};

// The one-step rule, for a start already beside the solution (a warm refit): from a start within
// a few σ, one Gauss–Newton step lands where the full iteration would (Le Cam's one-step
// estimator), and a cost-only pass at the step shows whether the linear model held: the cost fell
// by what it predicted. A quadratic cost falls by exactly that, and the mismatch, set by the terms
// beyond the quadratic, bounds the decrement left at the step from above (it is of higher order
// in the step's length). The start's evaluation, with its normal matrix (and whatever sums the
// caller's evaluation carries), then stands for the solution's, with the cost of the step.
// `cost_at(z)` returns an Evaluation whose `finite` and `cost` (at least) are z's; the accepted
// Evaluation takes them with its `adopt_cost(at_step)`.
struct NoCostAt {};

// Whether the first step is taken on the one-step rule; `at_step` receives its cost-only
// evaluation.
template <class Evaluation, class CostAt>
bool accept_one_step(CostAt& cost_at, const Eigen::VectorXd& z_new, const Evaluation& cur,
                     double predicted, double cost_per_observation, const LmSettings& settings,
                     Evaluation& at_step) {
  if (!(settings.one_step_tolerance > 0.0) || !z_new.allFinite()) return false;
  at_step = cost_at(z_new);
  if (at_step.stop != nullptr || !at_step.finite || !std::isfinite(at_step.cost)) return false;
  const double actual = cur.cost - at_step.cost;
  return std::abs(actual - predicted) <= settings.one_step_tolerance * cost_per_observation;
}

// `evaluate(z)` returns an Evaluation; `z` is the start; `cost_at(z)` serves the one-step rule.
template <class Evaluation, class Evaluate, class CostAt = NoCostAt>
LmOutcome<Evaluation> levenberg_marquardt(Evaluate&& evaluate, Eigen::VectorXd z,
                                          const LmSettings& settings, CostAt cost_at = {}) {
  LmOutcome<Evaluation> out;
  out.at_z = evaluate(z);
  out.z = z;
  if (out.at_z.stop != nullptr) {
    out.message = out.at_z.stop;
    return out;
  }
  if (!out.at_z.finite) {
    out.message = "model not finite at the start";
    return out;
  }
  const Evaluation start = out.at_z;
  const Eigen::Index n = z.size();
  double mu = settings.initial_damping, nu = 2.0;
  for (int it = 0; it < settings.max_iterations; ++it) {
    out.iterations = it + 1;
    const Evaluation& cur = out.at_z;
    Eigen::VectorXd d = cur.normal.diagonal().cwiseMax(0.0).cwiseSqrt();
    for (Eigen::Index i = 0; i < n; ++i)
      if (!(d[i] > 0.0) || !std::isfinite(d[i])) d[i] = 1.0;
    const Eigen::MatrixXd scaled =
        d.cwiseInverse().asDiagonal() * cur.normal * d.cwiseInverse().asDiagonal();
    const Eigen::VectorXd scaled_gradient = cur.gradient.cwiseQuotient(d);
    // Gauss–Newton decrement gᵀN⁻¹g: the cost reduction a full step would bring.
    Eigen::LDLT<Eigen::MatrixXd> gn(scaled);
    const double decrement =
        gn.info() == Eigen::Success ? scaled_gradient.dot(gn.solve(scaled_gradient)) : 1e300;
    const double cost_per_observation = cur.cost / std::max(1.0, settings.observations);
    if (cur.cost <= settings.cost_floor) {
      out.converged = true;
      out.message = "converged (residuals at rounding level)";
      return out;
    }
    if (std::isfinite(decrement) && decrement >= 0.0 &&
        decrement <= settings.decrement_tolerance * cost_per_observation) {
      out.converged = true;
      out.message = "converged";
      return out;
    }
    Eigen::MatrixXd damped = scaled;
    damped.diagonal().array() += mu;
    Eigen::LLT<Eigen::MatrixXd> llt(damped);
    if (llt.info() != Eigen::Success) {
      mu = mu > 0.0 ? mu * nu : kInitialDamping;
      nu *= 2.0;
      continue;
    }
    const Eigen::VectorXd step_scaled = llt.solve(scaled_gradient);
    const Eigen::VectorXd step = step_scaled.cwiseQuotient(d);
    // Predicted reduction of the linearized cost: 2δᵀg − δᵀNδ.
    const double predicted =
        2.0 * step_scaled.dot(scaled_gradient) - step_scaled.dot(scaled * step_scaled);
    const Eigen::VectorXd z_new = out.z + step;
    if constexpr (!std::is_same_v<CostAt, NoCostAt>) {
      if (it == 0 && predicted > 0.0) {
        Evaluation at_step;
        if (accept_one_step(cost_at, z_new, cur, predicted, cost_per_observation, settings,
                            at_step)) {
          out.z = z_new;
          out.at_z.adopt_cost(at_step);
          out.one_step = true;
          out.converged = true;
          out.message = "converged (one Gauss-Newton step)";
          return out;
        }
      }
    }
    Evaluation trial = evaluate(z_new);
    if (trial.stop != nullptr) {
      out.message = trial.stop;
      return out;
    }
    // A step to a non-finite z, a non-finite cost or an unsimulatable model is a failed step.
    if (trial.finite && std::isfinite(trial.cost) && z_new.allFinite() && trial.cost <= cur.cost) {
      const double cost_before = cur.cost;
      const double actual = cost_before - trial.cost;
      const double rho = predicted > 0.0 ? actual / predicted : 0.0;
      // Nielsen's update, but a step the linear model predicted well shrinks μ tenfold.
      mu *= rho > 0.75 ? 0.1 : std::max(1.0 / 3.0, 1.0 - std::pow(2.0 * rho - 1.0, 3));
      mu = std::max(mu, 1e-15);
      nu = 2.0;
      out.z = z_new;
      out.at_z = std::move(trial);
      // Stalled at the rounding floor: a further step cannot be told from zero.
      if (actual <= 1e-15 * cost_before) {
        out.converged = true;
        out.message = "converged (cost at rounding level)";
        return out;
      }
    } else {
      if (runs_past_resolution(start, cur, trial)) {
        out.stalled = true;
        out.message = "stalled: the step runs beyond the sampling's resolution";
        return out;
      }
      mu = mu > 0.0 ? mu * nu : kInitialDamping;
      nu *= 2.0;
      // The linear model promises less than the cost's own rounding can show: done.
      if (predicted <= 1e-12 * cur.cost) {
        out.converged = true;
        out.message = "converged (no decrease at rounding level)";
        return out;
      }
      if (mu > 1e20) {
        // Not even a tiny gradient step lowers the cost: the minimum to rounding precision, or
        // a model that cannot be simulated nearby.
        out.converged = std::isfinite(decrement) && decrement <= 1e-2 * cost_per_observation;
        out.message = out.converged ? "converged (no further decrease)" : "stalled: no decrease";
        return out;
      }
    }
  }
  out.message = "iteration limit";
  return out;
}

}  // namespace scp::refine

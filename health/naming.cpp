#include "health/naming.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace scp::health {

namespace {

// The best and the runner-up of one block's parameters, from one output's sums.
Naming name_in_block(const ProfiledSum& sum, int block, const Vector6& reference,
                     const NamingSettings& settings) noexcept {
  Naming out;
  out.block = block;
  Matrix6 information = Matrix6::Zero();
  for (int i = kBlockFirst[block]; i < kBlockEnd[block]; ++i)
    information(i, i) = sum.information(i, i);
  out.best = isolate(sum.score, information);
  const int b = out.best.parameter;
  if (b < 0) return out;
  const Vector6& glr = out.best.glr;
  for (int i = kBlockFirst[block]; i < kBlockEnd[block]; ++i)
    if (i != b && information(i, i) > 0.0 && (out.runner_up < 0 || glr[i] > glr[out.runner_up]))
      out.runner_up = i;
  const double misfit = sum.residual_square - glr[b] - static_cast<double>(sum.samples - 1);
  const double relative =
      reference[b] != 0.0 ? out.best.delta / reference[b] : std::numeric_limits<double>::infinity();
  const double linearization = 0.25 * relative * relative * glr[b];
  out.needed =
      needed_gap(std::max(std::isfinite(misfit) ? misfit : 0.0, linearization), settings.margin);
  out.gap = out.runner_up >= 0 ? glr[b] - glr[out.runner_up] : glr[b];
  out.definite = out.gap >= out.needed && std::abs(relative) >= settings.min_relative;
  for (int i = kBlockFirst[block]; i < kBlockEnd[block]; ++i)
    out.candidates[i] = information(i, i) > 0.0 && glr[b] - glr[i] < out.needed;
  return out;
}

}  // namespace

double needed_gap(double misfit_square, double margin) noexcept {
  if (!std::isfinite(misfit_square)) return std::numeric_limits<double>::infinity();
  return std::pow(std::sqrt(std::max(0.0, misfit_square)) + std::sqrt(margin), 2);
}

Naming name_change(const ProfiledSum& x, const ProfiledSum& tbar, const Vector6& reference,
                   const NamingSettings& settings) noexcept {
  // The thermal block moved when T̄'s best explanation stands out of T̄'s noise and misfit alike,
  // by a change that matters.
  const Naming thermal = name_in_block(tbar, 1, reference, settings);
  const int t = thermal.best.parameter;
  if (t >= 0 && thermal.best.glr[t] >= thermal.needed &&
      std::abs(thermal.best.delta) >= settings.min_relative * std::abs(reference[t]))
    return thermal;
  // The mechanical block is never named from the residuals: x's static gain is α2/k and its time
  // constant b/k whichever of θ1..θ4 moved, so their linearized responses differ by about as much
  // as a 10 % change's second-order term, which then decides (a k/m step named a2/m or b/m with
  // the wrong sign on simulated data, tests/health/test_naming.cpp). The refined window after
  // the onset names it (a nonlinear fit of every θ; HealthMonitor::name_from_window).
  Naming mechanical = name_in_block(x, 0, reference, settings);
  mechanical.definite = false;
  for (int i = kBlockFirst[0]; i < kBlockEnd[0]; ++i)
    mechanical.candidates[i] = x.information(i, i) > 0.0;
  return mechanical;
}

ChangeEvidence weigh_change(std::span<const ScoreBlock> blocks, double from,
                            const Vector6& reference, const NamingSettings& settings) {
  ChangeEvidence e;
  for (int k = 0; k < 2; ++k)
    e.outputs[static_cast<std::size_t>(k)] = profile_nuisance(blocks, from, k);
  e.name = name_change(e.outputs[0], e.outputs[1], reference, settings);
  return e;
}

}  // namespace scp::health

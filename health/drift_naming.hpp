#pragma once
// Which mechanical parameter a drift is, from the refined windows since it began.
//
// A constant-θ window of a plant whose damping drifts is a misfit: θ1..θ4 scatter together along
// their common scale (the mass, which only a sub-millisecond inertial lag determines) by 10–25 %,
// and no θ_i has a significant slope. The scale cancels in the ratios to k/m,
//
//   b/k = θ1/θ3,   α1/k = θ2/θ3,   α2/k = θ4/θ3 (the static gain),
//
// whose trends are clean: a drift of b moves b/k alone, of α1 α1/k alone, of α2 α2/k alone, and
// of k all three by the same relative rate (a mass drift moves none, and is not named). Each
// ratio's slope is fitted over the windows with their overlap (trend.hpp), its σ from the
// windows' covariance by the delta method, widened by the scatter about the line of the windows
// that share no data (a misfit's windows scatter beyond their own σ).

#include <span>

#include "health/monitor.hpp"

namespace scp::health {

struct DriftName {
  int parameter = -1;    // the θ index named, −1 when the ratios do not single one out
  ParameterTrend trend;  // its rate (relative per hour from the ratio's), σ, drifting = named
};

// `windows` in time order, all after the drift's onset; `z` the two-sided threshold of each
// ratio's slope test. Needs three windows that share no data, else names nothing.
DriftName name_mechanical_drift(std::span<const WindowEstimate> windows, double z);

}  // namespace scp::health

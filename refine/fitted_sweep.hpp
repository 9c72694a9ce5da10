#pragma once
// One pass over a window at a fit's solution, as fit() simulated it (its extensions, sensor lag,
// nuisance terms and voltage delay), handing each sample's model outputs and sensitivities to a
// visitor: for the checks made on a fit after it returned (refine/validate_fit.hpp,
// refine/switch_placement.hpp).

#include <array>
#include <cstddef>
#include <functional>
#include <span>

#include "refine/fit.hpp"
#include "refine/model_simulator.hpp"
#include "refine/parameters.hpp"

namespace scp::refine {

// The slots `fit` estimated: θ less `known`, the initial state, the nuisance terms it estimated
// and the extensions it kept.
FreeMask fitted_slots(const FitResult& fit, const std::array<bool, 6>& known);

// The extensions' coefficients `fit`'s model ran with.
Tempcos fitted_tempcos(const FitResult& fit);

struct FittedSample {
  std::size_t k = 0;
  const ModelState* state = nullptr;  // the simulated x, ẋ, T̄
  double x_model = 0.0;               // x as measured: the state's x plus the sensor's zero
  double tbar_model = 0.0;          // T̄ as measured: the lagged reading plus the ambient's terms
  double thermal_input = 0.0;       // V² over (t_{k−1}, t_k] as the model sees it
  const ParamVector* jx = nullptr;  // ∂x_model/∂p
  const ParamVector* jt = nullptr;  // ∂tbar_model/∂p
};

// Simulates `fit`'s model over `window` (the window it fitted: refine::prepare_window's output)
// and calls `visit` at every sample in order.
void sweep_fitted_model(std::span<const WindowSample> window, const FitResult& fit,
                        const std::function<void(const FittedSample&)>& visit);

}  // namespace scp::refine

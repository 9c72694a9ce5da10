#pragma once
// What not knowing the voltage's timing adds to θ's Cramér–Rao bound (cramer_rao_bound,
// refine/fit.hpp): the voltage's delay d, every switch d later than recorded (as a live link's
// fit estimates it, FitSettings::max_input_delay_s), one more unknown beside the fit's.
// With the information of (p, d) split as [[A, b], [bᵀ, c]] and s = c − bᵀA⁻¹b (d's information
// with p refitted), θ's bound grows by A⁻¹b bᵀA⁻¹ / s = σ_d²·g gᵀ: g = A⁻¹b is how far θ̂ moves
// per second by which a fit's voltage switches later than the data's, σ_d = 1/√s the delay's own
// bound. To first order the same two figures say how well a window tells the voltage's interval
// (refine/voltage_timing.hpp): a one-period shift T moves θ by g·T and costs Δχ² = (T/σ_d)².

#include <array>
#include <span>

#include "refine/fit.hpp"

namespace scp::refine {

struct VoltageDelayBound {
  bool ok = false;                  // false: the window cannot bound d (no switch to move)
  Matrix6 share = Matrix6::Zero();  // to add to cramer_rao_bound's θ block
  double delay_sigma_s = 0.0;       // σ_d
  Vector6 theta_per_second = Vector6::Zero();  // g's θ part, θ's shift per second of delay
};

// At the truth, with cramer_rao_bound's arguments; ∂/∂d by finite differences over a twentieth
// of the window's room to move its switches (latest_switch_delay).
VoltageDelayBound voltage_delay_bound(std::span<const WindowSample> window, const Vector6& theta,
                                      const InitialState& initial, const Vector2& noise_sigma,
                                      const std::array<bool, 6>& known = {},
                                      const NuisanceSettings& nuisance = {},
                                      const ExtensionSettings& extensions = {},
                                      const Tempcos& truth = {});

}  // namespace scp::refine

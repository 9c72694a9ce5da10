#pragma once
// Which parameter changed? After a fast alarm the candidates are the single-parameter
// explanations of the residuals since the onset, each with the state at every seed of the
// residual simulation and the output offsets free (score_blocks.hpp, profile_nuisance): their
// generalized likelihood ratios Λ_i = s̃_i²/Ĩ_ii. Each block is named from the output that sees
// it alone: θ5, θ6 from T̄ (x sees them only through T̄, which is measured, and x carries the
// mechanical reference's error), θ1..θ4 from x. The thermal block is the one that moved when
// T̄'s best explanation is significant, else the mechanical one, which these residuals never
// name definitely (name_change).
//
// Over the seconds after a step two parameters of a block can explain the residuals almost alike
// (θ5 and θ6 both heat T̄; θ1..θ4 share a common scale): only the trajectory's shape over a
// heating and cooling cycle tells them apart. And a residual m that no single-parameter change
// explains (the change's second-order term, the reference's error, the plant's unmodelled
// dynamics) can tilt that comparison: if c changed and the residual is c's response plus m, then
// Λ_b − Λ_c = |r⊥c|² − |r⊥b|² ≤ |m⊥c|² ≤ (‖m‖ + noise)² whatever b. So a name is definite only
// when Λ_best − Λ_runner_up ≥ (M + z)², with z² = `margin` (χ²₁) for the noise and M² the larger
// of the misfit the best explanation leaves beyond the noise (RSS − (n − 1)) and its own
// linearization's error, (δ/2)²·Λ_best for a relative change δ (the first neglected term of the
// response's expansion in δ). Until then the change is named as the set of parameters within
// (M + z)² of the best.

#include "health/score_blocks.hpp"

namespace scp::health {

// z² of the naming's margin: χ²₁ at 0.999.
inline constexpr double kNameMargin = 10.83;

struct Naming {
  Isolation best;              // the largest Λ_i in the block that moved, its change and σ
  int block = -1;              // 0 mechanical, 1 thermal
  int runner_up = -1;          // the second largest in that block
  double gap = 0.0;            // Λ_best − Λ_runner_up
  double needed = 0.0;         // (M + z)²
  bool definite = false;       // gap ≥ needed
  ParameterMask candidates{};  // the parameters within `needed` of the best
};

// `x` and `tbar`: each output's sums since the onset (profile_nuisance's output 0 and 1);
// `reference`: the θ the residuals are against. A change below `min_relative` of |θ_i| is never
// named, nor makes its block the one that moved: at N1's 1e-3 °C a thermal reference error of
// 1e-5 relative becomes significant in T̄ within a minute (HealthSettings::min_relative_change).
// (M + z)² with M² = max(0, misfit_square) and z² = margin: the gap a name needs when its best
// explanation leaves misfit_square beyond the noise (the header's argument; also the refined
// window's naming, HealthMonitor::name_from_window). Infinite for a non-finite misfit.
double needed_gap(double misfit_square, double margin) noexcept;

struct NamingSettings {
  double margin = kNameMargin;
  double min_relative = 0.0;
};
Naming name_change(const ProfiledSum& x, const ProfiledSum& tbar, const Vector6& reference,
                   const NamingSettings& settings) noexcept;

// The blocks from `from` on: each output's profiled sums and the name they give. Parameter i's
// change alone is outputs[block_of(i)]'s s̃_i/Ĩ_ii with σ 1/√Ĩ_ii.
struct ChangeEvidence {
  std::array<ProfiledSum, 2> outputs;
  Naming name;
};
ChangeEvidence weigh_change(std::span<const ScoreBlock> blocks, double from,
                            const Vector6& reference, const NamingSettings& settings);

}  // namespace scp::health

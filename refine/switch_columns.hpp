#pragma once
// What the placed voltage switches' phases (refine/switch_placement.hpp) explain of T̄, at the
// validator's block layout (refine/validation.hpp): so that the whiteness test counts them among
// what the fit explains.

#include <Eigen/Core>
#include <span>

#include "refine/fit.hpp"
#include "refine/validation.hpp"

namespace scp::refine {

// The placed phases' sensitivities of T̄'s reading at `fit` on `prepared` as it placed them, as
// block means at `layout` (rows: layout's blocks; a column per switch row, in order): what the
// phases explain of ε_T, for ResidualValidator::finish (each phase explains a few blocks after
// its switch, so that a whiteness test that ignored them would read the fit's doing as colour).
// Empty (no columns) where nothing is placed, or the projection would cost more than
// kMostProjectedPhaseWork (rows × switches²).
Eigen::MatrixXd placed_switch_columns(std::span<const WindowSample> prepared, const FitResult& fit,
                                      const BlockLayout& layout);

// The whiteness test's recursive residuals over blocks × switches cost blocks × switches² (a
// fifth of a second at this many): beyond it, the test stays Ljung–Box's (docs/validation.md).
inline constexpr double kMostProjectedPhaseWork = 2e8;

}  // namespace scp::refine

#pragma once
// Covariance of the weighted least-squares estimate over the free coordinates of p.
//
// White: (JᵀWJ)⁻¹ with W = diag(1/σ̂²) from the residuals — the Cramér–Rao covariance when the
// sensor noise is white and Gaussian.
// Newey–West (HAC): (JᵀWJ)⁻¹ S (JᵀWJ)⁻¹ with S the Bartlett-weighted long-run covariance of the
// score s_k = J_kᵀW r_k. For white residuals S ≈ JᵀWJ and the two agree; for coloured sensor noise
// (a low-pass in the sensor, mains pickup) neighbouring residuals carry the same information
// twice and the white covariance is too small by about the noise's correlation time in samples.

#include <array>
#include <cstddef>

#include "refine/model_simulator.hpp"

namespace scp::refine {

using FreeMask = std::array<bool, kParams>;

// The inverse of `normal` restricted to the free coordinates (zero rows and columns elsewhere);
// false when that block is not positive definite.
bool inverse_on_free(const Matrix9& normal, const FreeMask& free, Matrix9& inverse);

// (N⁻¹) S (N⁻¹) on the free coordinates.
bool sandwich_on_free(const Matrix9& normal, const Matrix9& long_run, const FreeMask& free,
                      Matrix9& covariance);

// Newey–West lags for N samples whose residuals have lag-one autocorrelation rho: the larger of
// Newey and West's fixed rule floor(4·(N/100)^(2/9)) and Andrews' (1991) AR(1) plug-in for the
// Bartlett kernel, 1.1447·(α N)^(1/3) with α = 4ρ²/((1−ρ)²(1+ρ)²). The fixed rule alone gives 23
// lags at N = 3e5, too few for noise correlated over ~10 samples (it would cover ~60 % of the
// long-run variance); the plug-in follows the measured colour. Capped at N/10.
int automatic_hac_lags(std::size_t samples, double rho);

}  // namespace scp::refine

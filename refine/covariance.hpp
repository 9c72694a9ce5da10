#pragma once
// Covariance of the weighted least-squares estimate over the free coordinates of p.
//
// White: (JᵀWJ)⁻¹ with W = diag(1/σ̂²) from the residuals — the Cramér–Rao covariance when the
// sensor noise is white and Gaussian.
// Newey–West (HAC): (JᵀWJ)⁻¹ S (JᵀWJ)⁻¹ with S the Bartlett-weighted long-run covariance of the
// score s_k = J_kᵀW r_k. For white residuals S ≈ JᵀWJ and the two agree; for coloured sensor noise
// (a low-pass in the sensor, mains pickup) neighbouring residuals carry the same information
// twice and the white covariance is too small by about the noise's correlation time in samples.
// Batch means: the same sandwich with S from the score summed over K contiguous batches, which
// sees correlation however far it reaches within a batch. Newey–West's lags follow the residuals'
// lag-one correlation, so an error that is small per sample but slow (a link's landings put
// seconds-long errors into x under a jitter that is white per sample) escapes it; the batch means
// are the check on it.

#include <array>
#include <cstddef>
#include <span>

#include "refine/parameters.hpp"

namespace scp::refine {

// The inverse of `normal` restricted to the free coordinates (zero rows and columns elsewhere);
// false when that block is not positive definite.
bool inverse_on_free(const ParamMatrix& normal, const FreeMask& free, ParamMatrix& inverse);

// (N⁻¹) S (N⁻¹) on the free coordinates.
bool sandwich_on_free(const ParamMatrix& normal, const ParamMatrix& long_run, const FreeMask& free,
                      ParamMatrix& covariance);

// The batch-means check on `covariance` (Newey–West's) from the score g_b and the information
// H_b summed over K contiguous batches of the window (PassResult::batch_scores,
// batch_information), N = Σ H_b. The batch-means covariance is N⁻¹(Σ g_b g_bᵀ)N⁻¹. Two things
// make it differ from Newey–West's even when both are right, and both are taken into account:
// - at θ̂ the scores sum to zero, which removes Σ_b H_b N⁻¹ H_b from E[Σ g_b g_bᵀ] (with equal
//   batches a 1/K share: K/(K−1), the usual correction); here it is computed from the H_b, since
//   an excitation's information is rarely equal across batches;
// - with unequal batches the K terms do not count alike, and the zero sum ties them: the
//   batch-means variance of θ_i is a quadratic form in Gaussian scores whose mean and variance
//   follow from the H_b exactly (refine/covariance.cpp), a χ² of ν_i = (tr M)²/tr M² degrees of
//   freedom (Satterthwaite), fewer than K (on the paper's excitation: docs/numerics.md, "A
//   consistent estimate").
// A coordinate whose corrected batch-means variance exceeds Newey–West's beyond the 99 % point of
// χ²_ν/ν is scaled by √(ratio); the others keep factor 1. `covariance` becomes D·covariance·D,
// its correlations kept. At 99 % one white-noise window in a hundred is scaled for nothing; what
// the check lets through is a σ at most √(χ²_ν(0.99)/ν) too small.
struct BatchMeansCheck {
  ParamVector factor = ParamVector::Ones();  // what scaled each σ (1: not significant, or not free)
  ParamVector ratio = ParamVector::Zero();   // corrected batch-means variance / Newey–West's
  ParamVector dof = ParamVector::Zero();     // ν_i
};

BatchMeansCheck check_against_batch_means(ParamMatrix& covariance, const ParamMatrix& normal,
                                          std::span<const ParamVector> batch_scores,
                                          std::span<const ParamMatrix> batch_information,
                                          const FreeMask& free);

// The 99 % point of χ²_ν / ν (Wilson–Hilferty: within 1 % for ν ≥ 2,
// tests/refine/test_covariance.cpp).
double chi_square_99_over_dof(double dof);

// Newey–West lags for N samples whose residuals have lag-one autocorrelation rho: the larger of
// Newey and West's fixed rule floor(4·(N/100)^(2/9)) and Andrews' (1991) AR(1) plug-in for the
// Bartlett kernel, 1.1447·(α N)^(1/3) with α = 4ρ²/((1−ρ)²(1+ρ)²). The fixed rule alone gives 23
// lags at N = 3e5, too few for noise correlated over ~10 samples (it would cover ~60 % of the
// long-run variance); the plug-in follows the measured colour. Capped at N/10.
int automatic_hac_lags(std::size_t samples, double rho);

}  // namespace scp::refine

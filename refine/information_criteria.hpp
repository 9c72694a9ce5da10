#pragma once
// Information criteria for choosing a model structure from one window: whether an extension (a
// temperature coefficient, a nuisance term) earns its place. The refined fit compares the
// criterion of the model with and without it, fitted to the same window; the lower wins.

#include <cstddef>
#include <span>

namespace scp::refine {

// One output's residuals after a fit: their sum of squares and how many there were.
struct ChannelResiduals {
  double rss = 0.0;
  std::size_t samples = 0;
};

// −2 ln L at the maximum for independent Gaussian channels, each with its own variance estimated
// with the rest (σ̂²_c = RSS_c/N_c): Σ_c N_c·(ln(2π·RSS_c/N_c) + 1). A channel with no samples
// counts nothing; NaN when a channel with samples has an RSS that is not positive and finite (a
// noise-free fit's 0 has no likelihood to compare: ln 0 = −∞).
double gaussian_deviance(std::span<const ChannelResiduals> channels) noexcept;

// Schwarz's BIC = −2 ln L + k·ln n, with n = Σ N_c scalar observations and k every estimated
// quantity (θ's free parameters, the initial state, nuisance terms, extension parameters, and the
// channels' variances). Consistent: with a true model in the set it picks it with probability →
// 1; an extension worth a decrease Δ(−2 ln L) ≈ χ²₁ on data without it enters only when χ²₁ >
// ln n (13 at 300 000 samples: a false alarm of 3e-4). The likelihood counts each sample as
// independent: residuals coloured over many samples make a spurious extension look stronger.
// NaN as gaussian_deviance, or with no samples.
double bic(std::span<const ChannelResiduals> channels, int parameters) noexcept;

// Young's YIC for one output: ln(σ̂²/σ_y²) + ln((1/p)·Σ_i var(θ̂_i)/θ̂_i²), the residual variance
// relative to the output's and the parameters' mean normalized variance (var(θ̂_i) = σ̂²·p̂_ii,
// the covariance's diagonal). Strongly negative is good; an extension whose parameter the window
// cannot determine raises it even when it lowers the residual. NaN for p = 0, a zero estimate or
// a non-positive variance.
double yic(double residual_variance, double output_variance, std::span<const double> estimates,
           std::span<const double> variances) noexcept;

}  // namespace scp::refine

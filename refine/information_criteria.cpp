#include "refine/information_criteria.hpp"

#include <cmath>
#include <limits>
#include <numbers>

namespace scp::refine {

double gaussian_deviance(std::span<const ChannelResiduals> channels) noexcept {
  double d = 0.0;
  for (const ChannelResiduals& c : channels) {
    if (c.samples == 0) continue;
    // ln 0 = −∞: a perfect channel would make every comparison −∞ − (−∞) = NaN anyway.
    if (!(c.rss > 0.0) || !std::isfinite(c.rss)) return std::numeric_limits<double>::quiet_NaN();
    const double n = static_cast<double>(c.samples);
    d += n * (std::log(2.0 * std::numbers::pi * c.rss / n) + 1.0);
  }
  return d;
}

double bic(std::span<const ChannelResiduals> channels, int parameters) noexcept {
  std::size_t n = 0;
  for (const ChannelResiduals& c : channels) n += c.samples;
  if (n == 0) return std::numeric_limits<double>::quiet_NaN();
  return gaussian_deviance(channels) + parameters * std::log(static_cast<double>(n));
}

double yic(double residual_variance, double output_variance, std::span<const double> estimates,
           std::span<const double> variances) noexcept {
  const std::size_t p = estimates.size();
  if (p == 0 || variances.size() != p || !(residual_variance > 0.0) || !(output_variance > 0.0))
    return std::numeric_limits<double>::quiet_NaN();
  double mean = 0.0;
  for (std::size_t i = 0; i < p; ++i) {
    if (estimates[i] == 0.0 || !(variances[i] > 0.0))
      return std::numeric_limits<double>::quiet_NaN();
    mean += variances[i] / (estimates[i] * estimates[i]);
  }
  mean /= static_cast<double>(p);
  return std::log(residual_variance / output_variance) + std::log(mean);
}

}  // namespace scp::refine

// The model's extensions chosen by the data (refine/stages.hpp, select_extensions): backward
// elimination from the model with every extension asked for, by Schwarz's BIC. Backward because
// the paper's model alone can be far from the data that need an extension (a heater whose R rises
// 0.4 %/°C leaves it ×50 off, or stalled), while the extended model contains both: an extension
// the data do not need fits to about 0 and drops at once.
#include <cmath>
#include <limits>

#include "refine/information_criteria.hpp"
#include "refine/stages.hpp"
#include "refine/switch_placement.hpp"
#include "refine/warm_start.hpp"

namespace scp::refine {

namespace {

// `settings` with every `auto` extension set to `mode`.
FitSettings automatic_as(const FitSettings& settings, ExtensionMode mode) {
  FitSettings out = settings;
  for (const ExtensionSlot& e : kExtensionTable)
    if (out.extensions.*e.mode == ExtensionMode::automatic) out.extensions.*e.mode = mode;
  return out;
}

// BIC of a fit under `settings`: both channels' residuals, every slot it estimated and the two
// noise variances. NaN where the fit has no residuals to count (it did not reach its covariance).
double criterion(const FitResult& r, const FitSettings& settings) {
  if (!r.validated || r.samples == 0) return std::numeric_limits<double>::quiet_NaN();
  const double n = static_cast<double>(r.samples);
  const ChannelResiduals channels[2] = {{r.residual_rms[0] * r.residual_rms[0] * n, r.samples},
                                        {r.residual_rms[1] * r.residual_rms[1] * n, r.samples}};
  int parameters = 2;
  for (const bool f : fit_slots(settings)) parameters += f ? 1 : 0;
  return bic(channels, parameters);
}

// The fit's extensions reported as asked: each one's mode as configured, and for `auto` the
// criterion's verdict from `decided`.
void report_modes(const FitSettings& asked, const Extensions& decided, FitResult& result) {
  for (const ExtensionSlot& e : kExtensionTable) {
    ExtensionEstimate& out = result.extensions.*e.estimate;
    out.mode = asked.extensions.*e.mode;
    if (out.mode != ExtensionMode::automatic) continue;
    out.criterion = (decided.*e.estimate).criterion;
    out.criterion_difference = (decided.*e.estimate).criterion_difference;
  }
}

// An extension whose Wald statistic (value/σ)² at the model that has it exceeds this is kept
// without fitting the model that lacks it: the likelihood ratio that refit would measure is about
// the statistic, far beyond Schwarz's price (ln n, 13.3 at 300 s at 1 kHz), and a model that far
// from the data walks its budget's worth of iterations to its own minimum (light-stiff with
// ρ = 0.004: 232 iterations, 33 s of a 37 s fit). An extension the data do not need has a
// statistic of order 1 (χ²₁). At phases placed for the model with it, the statistic counts what
// the phases absorbed too (up to 92 for a term the choice then dropped), so there the screen
// waits for a hundred times that.
double kept_without_refit(ExtensionWeighing weighing) {
  return weighing == ExtensionWeighing::own_phases ? 1e4 : 100.0;
}

// (value/σ)² of an extension's estimate; 0 where it has no σ.
double wald_statistic(const ExtensionEstimate& e) {
  if (!(e.sigma > 0.0) || !std::isfinite(e.value)) return 0.0;
  const double z = e.value / e.sigma;
  return z * z;
}

// Schwarz's price of one parameter in `fit`: ln of its observations (both channels).
double price_of_one(const FitResult& fit) {
  return std::log(2.0 * static_cast<double>(fit.samples));
}

// What a model is weighed by: its BIC, and at placed switches (ExtensionWeighing::own_phases)
// less the cost phases of its own would take off it.
double weigh(std::span<const WindowSample> prepared, const FitResult& r,
             const FitSettings& settings, ExtensionWeighing weighing) {
  const double value = criterion(r, settings);
  if (weighing != ExtensionWeighing::own_phases || !std::isfinite(value)) return value;
  return value - placement_decrease(prepared, r, settings.known);
}

}  // namespace

FitResult fit_extended(std::span<const WindowSample> prepared, const Vector6& theta_start,
                       const FitSettings& settings) {
  FitResult extended = fit_staged(prepared, theta_start, automatic_as(settings, ExtensionMode::on));
  if (extended.converged) return extended;
  // The extended model could not be fitted here: the model without the automatic ones.
  FitResult base = fit_staged(prepared, theta_start, automatic_as(settings, ExtensionMode::off));
  base.iterations += extended.iterations;
  base.evaluations += extended.evaluations;
  report_modes(settings, Extensions{}, base);
  return base;
}

bool is_extended(const FitResult& fit, const FitSettings& settings) {
  for (const ExtensionSlot& e : kExtensionTable)
    if (settings.extensions.*e.mode == ExtensionMode::automatic &&
        !(fit.extensions.*e.estimate).kept)
      return false;
  return fit.converged;
}

FitResult eliminate_extensions(std::span<const WindowSample> prepared, FitResult current,
                               const FitSettings& settings, ExtensionWeighing weighing) {
  FitSettings current_settings = automatic_as(settings, ExtensionMode::on);
  int iterations = current.iterations, evaluations = current.evaluations;
  Extensions decided;
  double current_value = weigh(prepared, current, current_settings, weighing);
  for (const ExtensionSlot& e : kExtensionTable) {
    if (settings.extensions.*e.mode != ExtensionMode::automatic) continue;
    ExtensionEstimate& verdict = decided.*e.estimate;
    verdict.criterion = InformationCriterion::bic;
    if (const double wald = wald_statistic(current.extensions.*e.estimate);
        wald > kept_without_refit(weighing)) {
      verdict.criterion_difference = price_of_one(current) - wald;  // the likelihood ratio's
      continue;
    }
    FitSettings trial = current_settings;
    trial.extensions.*e.mode = ExtensionMode::off;
    WarmStart from = warm_start(current, current_settings, prepared.front());
    (from.extensions.*e.estimate).kept = false;
    FitResult without = joint_refit(prepared, from, trial, settings.max_iterations);
    iterations += without.iterations;
    evaluations += without.evaluations;
    const double without_value = weigh(prepared, without, trial, weighing);
    verdict.criterion_difference = current_value - without_value;
    // Kept unless the model without it converged and is no worse by the criterion.
    if (without.converged && !(verdict.criterion_difference < 0.0)) {
      current = without;
      current_settings = trial;
      current_value = without_value;
    }
  }
  current.iterations = iterations;
  current.evaluations = evaluations;
  report_modes(settings, decided, current);
  return current;
}

FitResult select_extensions(std::span<const WindowSample> prepared, const Vector6& theta_start,
                            const FitSettings& settings) {
  FitResult extended = fit_extended(prepared, theta_start, settings);
  if (!is_extended(extended, settings)) return extended;
  return eliminate_extensions(prepared, std::move(extended), settings, ExtensionWeighing::bic);
}

FitResult reselect_extensions(std::span<const WindowSample> prepared, const FitResult& fitted,
                              const FitSettings& settings) {
  if (is_extended(fitted, settings)) {
    FitResult start = fitted;  // whose cost its caller counts
    start.iterations = start.evaluations = 0;
    return eliminate_extensions(prepared, std::move(start), settings,
                                ExtensionWeighing::own_phases);
  }
  // Every `auto` extension freed from where `fitted` left it (0 where it was dropped).
  const FitSettings extended = automatic_as(settings, ExtensionMode::on);
  FitResult current = joint_refit(prepared, warm_start(fitted, extended, prepared.front()),
                                  extended, settings.max_iterations);
  if (!current.converged) return current;
  return eliminate_extensions(prepared, std::move(current), settings,
                              ExtensionWeighing::own_phases);
}

}  // namespace scp::refine

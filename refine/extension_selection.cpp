// The model's extensions chosen by the data (refine/stages.hpp, select_extensions): backward
// elimination from the model with every extension asked for, by Schwarz's BIC. Backward because
// the paper's model alone can be far from the data that need an extension (a heater whose R rises
// 0.4 %/°C leaves it ×50 off, or stalled), while the extended model contains both: an extension
// the data do not need fits to about 0 and drops at once.
#include <cmath>
#include <limits>

#include "refine/information_criteria.hpp"
#include "refine/stages.hpp"
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

}  // namespace

FitResult select_extensions(std::span<const WindowSample> prepared, const Vector6& theta_start,
                            const FitSettings& settings) {
  FitSettings current_settings = automatic_as(settings, ExtensionMode::on);
  FitResult current = fit_staged(prepared, theta_start, current_settings);
  int iterations = current.iterations, evaluations = current.evaluations;
  Extensions decided;
  if (!current.converged) {
    // The extended model could not be fitted here: the model without the automatic ones.
    FitResult base = fit_staged(prepared, theta_start, automatic_as(settings, ExtensionMode::off));
    base.iterations += iterations;
    base.evaluations += evaluations;
    report_modes(settings, decided, base);
    return base;
  }
  double current_bic = criterion(current, current_settings);
  for (const ExtensionSlot& e : kExtensionTable) {
    if (settings.extensions.*e.mode != ExtensionMode::automatic) continue;
    FitSettings trial = current_settings;
    trial.extensions.*e.mode = ExtensionMode::off;
    WarmStart from = warm_start(current, current_settings, prepared.front());
    (from.extensions.*e.estimate).kept = false;
    FitResult without = joint_refit(prepared, from, trial, settings.max_iterations);
    iterations += without.iterations;
    evaluations += without.evaluations;
    const double without_bic = criterion(without, trial);
    ExtensionEstimate& verdict = decided.*e.estimate;
    verdict.criterion = InformationCriterion::bic;
    verdict.criterion_difference = current_bic - without_bic;
    // Kept unless the model without it converged and is no worse by the criterion.
    if (without.converged && !(verdict.criterion_difference < 0.0)) {
      current = without;
      current_settings = trial;
      current_bic = without_bic;
    }
  }
  current.iterations = iterations;
  current.evaluations = evaluations;
  report_modes(settings, decided, current);
  return current;
}

}  // namespace scp::refine

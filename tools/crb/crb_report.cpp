#include "tools/crb/crb_report.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

#include "refine/switch_placement.hpp"
#include "refine/voltage_delay_bound.hpp"

namespace scp::tools::crb {

nlohmann::json crb_report(const Experiment& e, const NoiseLevel& noise,
                          const std::array<bool, 6>& known, double ambient_c,
                          double temperature_max_c, const refine::NuisanceSettings& nuisance,
                          const refine::ExtensionSettings& extensions, TimingUnknowns timing) {
  if (!(std::isfinite(noise.x) && noise.x > 0.0 && std::isfinite(noise.temperature) &&
        noise.temperature > 0.0)) {
    throw std::invalid_argument(
        "the bound needs sensor noise > 0 on x and on T (a noise-free channel would fix θ "
        "exactly): set driver.sim.noise.x and .temperature, or --noise-x and --noise-temperature");
  }
  // An estimated lag is bounded at the plant's (a held one at its declared value).
  refine::NuisanceSettings at_truth = nuisance;
  if (!at_truth.sensor_lag.fixed) at_truth.sensor_lag.value = e.sensor_lag_s;
  const refine::Vector2 sigma_noise(noise.x, noise.temperature);
  refine::Matrix6 cov = refine::cramer_rao_bound(e.window, e.theta, e.initial, sigma_noise, known,
                                                 at_truth, extensions, e.tempcos);
  const refine::Matrix6 known_timing = cov;
  std::size_t switches = 0;
  if (timing.switch_phases)
    cov += refine::switch_phases_bound_share(e.window, e.theta, e.initial, sigma_noise, known,
                                             at_truth, extensions, e.tempcos, switches);
  nlohmann::json delay = {{"bounded", timing.voltage_delay}};
  if (timing.voltage_delay) {
    // The fit tells the voltage's timing from T̄ with the sensor's lag held (refine/
    // voltage_timing.hpp: on T̄ a one-period shift and a lag of a period are one model, and only
    // x, through the mechanical block, tells them apart): the delay is bounded so too, and what
    // a free lag would leave of it is reported beside.
    refine::NuisanceSettings lag_held = at_truth;
    lag_held.sensor_lag.fixed = true;
    const refine::VoltageDelayBound d = refine::voltage_delay_bound(
        e.window, e.theta, e.initial, sigma_noise, known, lag_held, extensions, e.tempcos);
    if (!at_truth.sensor_lag.fixed) {
      const refine::VoltageDelayBound free_lag = refine::voltage_delay_bound(
          e.window, e.theta, e.initial, sigma_noise, known, at_truth, extensions, e.tempcos);
      delay["lag_free_sigma_s"] = free_lag.ok ? nlohmann::json(free_lag.delay_sigma_s) : nullptr;
    }
    if (d.ok) {
      cov += d.share;
      delay["sigma_s"] = d.delay_sigma_s;
      const double shift_over_sigma = e.period_s / d.delay_sigma_s;
      delay["one_period_chi2"] = shift_over_sigma * shift_over_sigma;
      nlohmann::json shifts = nlohmann::json::array();
      for (int i = 0; i < 6; ++i) {
        const double s = known_timing(i, i) > 0.0 ? std::sqrt(known_timing(i, i)) : NAN;
        const double moved = std::fabs(d.theta_per_second[i]) * e.period_s / s;
        shifts.push_back(std::isfinite(moved) ? nlohmann::json(moved) : nlohmann::json());
      }
      delay["one_period_shift_sigmas"] = std::move(shifts);
    } else {
      cov.setConstant(std::numeric_limits<double>::infinity());  // no switch: d unbounded
    }
  }

  std::vector<double> theta(6), sigma(6), rel(6);
  std::vector<bool> known_list(6);
  for (int i = 0; i < 6; ++i) {
    const auto u = static_cast<std::size_t>(i);
    theta[u] = e.theta[i];
    // A bound that is not a finite non-negative variance is reported as null, not as a number.
    const double var = cov(i, i);
    sigma[u] = std::isfinite(var) && var >= 0.0 ? std::sqrt(var) : NAN;
    rel[u] = sigma[u] / std::fabs(theta[u]);
    known_list[u] = known[u];
  }
  auto finite_or_null = [](const std::vector<double>& v) {
    nlohmann::json a = nlohmann::json::array();
    for (const double d : v) a.push_back(std::isfinite(d) ? nlohmann::json(d) : nlohmann::json());
    return a;
  };
  nlohmann::json out;
  out["theta"] = theta;
  out["crb_sigma"] = finite_or_null(sigma);
  out["crb_rel"] = finite_or_null(rel);
  out["known"] = known_list;
  nlohmann::json estimated = nlohmann::json::array();
  if (!nuisance.x_zero.fixed) estimated.push_back("x_zero");
  if (!nuisance.ambient_offset.fixed) estimated.push_back("ambient_offset");
  if (!nuisance.ambient_drift.fixed) estimated.push_back("ambient_drift");
  if (!nuisance.sensor_lag.fixed) estimated.push_back("sensor_lag");
  out["nuisance_estimated"] = std::move(estimated);
  nlohmann::json extended = nlohmann::json::array();
  if (extensions.resistance_tempco != refine::ExtensionMode::off)
    extended.push_back("resistance_tempco");
  if (extensions.stiffness_softening != refine::ExtensionMode::off)
    extended.push_back("stiffness_softening");
  if (extensions.cooling_tempco != refine::ExtensionMode::off) extended.push_back("cooling_tempco");
  out["extensions_estimated"] = std::move(extended);
  out["switch_phases"] = {{"bounded", timing.switch_phases}, {"switches", switches}};
  out["voltage_delay"] = std::move(delay);
  out["noise"] = {{"x", noise.x}, {"temperature", noise.temperature}};
  out["period_s"] = e.period_s;
  out["duration_s"] = e.duration_s;
  out["window"] = {
      {"t_begin", e.window.front().t}, {"t_end", e.window.back().t}, {"samples", e.window.size()}};
  out["initial_state"] = {e.initial[0], e.initial[1], e.initial[2]};
  out["excitation"] = {
      {"mean_v", e.mean_voltage}, {"mean_v2", e.mean_voltage_sq}, {"max_v", e.max_voltage}};
  const double max_temperature = e.max_tbar + ambient_c;
  out["thermal"] = {{"mean_tbar", e.mean_tbar},
                    {"max_tbar", e.max_tbar},
                    {"max_temperature_c", max_temperature},
                    {"temperature_max_c", temperature_max_c},
                    {"within_limit", max_temperature < temperature_max_c}};
  return out;
}

}  // namespace scp::tools::crb

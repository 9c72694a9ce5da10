#pragma once
// The Cramér–Rao bound of an experiment and what the experiment costs, as one JSON object
// (scp-crb's output; scripts/montecarlo reads it).

#include <array>
#include <nlohmann/json.hpp>

#include "refine/fit_terms.hpp"
#include "tools/crb/experiment.hpp"

namespace scp::tools::crb {

struct NoiseLevel {
  double x = 0.0;            // m, standard deviation of the position sensor
  double temperature = 0.0;  // °C
};

// Calls refine::cramer_rao_bound() on the experiment's window, the nuisance terms that `nuisance`
// leaves free estimated alongside (as the daemon's fit estimates them: refine.nuisance), and the
// model's extensions that `extensions` does not leave off (at the plant's coefficients), and
// returns
//   theta, crb_sigma (absolute), crb_rel (σ/|θ|), known, nuisance_estimated and
//   extensions_estimated (names), noise, window
//   {t_begin, t_end, samples}, initial_state, excitation {mean_v, mean_v2, max_v}, thermal
//   {mean_tbar, max_tbar, max_temperature_c, temperature_max_c, within_limit}.
// With `switch_phases` (the excitation's switches at phases of their own: a generator on a clock
// of its own, as scp-benchsim --generator-clock-ppm makes it) the phases are bounded as unknowns
// beside θ (refine::switch_phases_bound_share), and switch_phases {bounded, switches} says so.
// With `voltage_delay` (the voltage's timing not known: a replay of unknown provenance, whose
// interval the fit estimates, or a live link's refine.link_timing: estimate) the voltage's delay
// is bounded as one more unknown (refine::voltage_delay_bound) with the sensor's lag held at the
// plant's, as the fit tells the voltage's interval, and voltage_delay {bounded, sigma_s,
// one_period_chi2, one_period_shift_sigmas, lag_free_sigma_s} says what it costs: σ_d, the Δχ²
// that tells a one-period shift of the interval, how many of θ's known-timing σ that shift moves
// each θ, and (where the lag is estimated) σ_d with the lag free too, which only x constrains.
// Throws std::invalid_argument when a noise level is not > 0 (a noise-free channel has no bound).
struct TimingUnknowns {
  bool switch_phases = false;
  bool voltage_delay = false;
};
nlohmann::json crb_report(const Experiment& experiment, const NoiseLevel& noise,
                          const std::array<bool, 6>& known, double ambient_c,
                          double temperature_max_c, const refine::NuisanceSettings& nuisance = {},
                          const refine::ExtensionSettings& extensions = {},
                          TimingUnknowns timing = {});

}  // namespace scp::tools::crb

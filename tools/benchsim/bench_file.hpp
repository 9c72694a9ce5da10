#pragma once
// A replay file (drivers/replay/csv_trace.hpp) of a simulated bench that is wrong the ways a real
// one is (drivers/sim/plant_params.hpp, PlantDeviations; the sensors of SimSettings), made by an
// integrator other than the fit's: all states by RK4 at fine sub-steps, with the voltage either
// continuous in time (cut at every switch of a step or PRBS bit) or held by a DAC over each
// period. Test data for the refinement that is not the refinement's own discretization.

#include <iosfwd>
#include <string>
#include <string_view>

#include "drivers/sim/sim_settings.hpp"
#include "excitation/excitation_settings.hpp"
#include "tools/benchsim/analog_voltage.hpp"

namespace scp::tools::benchsim {

// How the file's V relates to the voltage the actuator saw.
enum class VoltageTiming {
  // V(t) varies continuously (an analog source); each row's V is its value at the row's t.
  // Replay with estimator.voltage_hold: foh.
  continuous,
  // A DAC holds the command issued at each row's t until the next row. Each row's V is the
  // voltage applied over the interval BEFORE it (the daemon's convention, Sample::voltage;
  // the file has a V_since column, blank: over the whole interval). Row 0's V is 0 V.
  dac_before,
  // As dac_before, but each row's V is the command issued at the row's t, applied over the
  // interval AFTER it (a lab script logging its command). No V_since column.
  dac_after,
};

// Parses "continuous", "dac-before" or "dac-after"; throws std::invalid_argument naming them.
VoltageTiming parse_voltage_timing(std::string_view name);
std::string_view name_of(VoltageTiming timing) noexcept;

// The sensor noise levels of scripts/montecarlo (standard deviations on x, ẋ, T).
// Throws std::invalid_argument for a name other than N0..N3.
void apply_noise_level(std::string_view level, drivers::sim::SimSettings& sim);

struct BenchFile {
  // The plant (Table I by default), its deviations, the sensors, their noise and seed, the
  // configured ambient, the RK4 sub-steps per ms. Validated as SimDriver validates it.
  drivers::sim::SimSettings sim;
  excitation::ExcitationSettings excitation;  // the paper's four sines by default
  bool excite = true;                         // false: 0 V throughout
  VoltageTiming timing = VoltageTiming::continuous;
  GeneratorClock clock;  // the source's clock; the DAQ's by default (switches on the rows)
  double duration_s = 300.0;
  double period_s = 1e-3;  // rows at t = k·period_s, k = 0 .. duration_s/period_s
};

BenchFile default_bench_file();  // Table I, the paper's excitation, continuous, N0

// Writes the file: '#' lines saying what made it (settings, true θ), the header
// t,x,xdot,T,V[,V_since][,I], one row per period, each number the shortest text that reads back
// as the same double. I (A) is written when sim.measure_current: the current at the row's t from
// the voltage applied just before it. Throws std::invalid_argument or DriverError on invalid
// settings, before writing anything.
void write_bench_file(const BenchFile& file, std::ostream& out);

}  // namespace scp::tools::benchsim

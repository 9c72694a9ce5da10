#pragma once
// An excitation (excitation/excitation_settings.hpp) as a voltage continuous in time, for a bench
// whose source is not a DAC: the sines at every instant, the steps and the PRBS bits switching at
// their own instants rather than at sample instants.

#include "excitation/excitation.hpp"
#include "excitation/excitation_settings.hpp"

namespace scp::tools::benchsim {

// The source's own clock against the DAQ's: the generator reads g(t) = t·(1 + rate_error) + offset.
// A crystal's tens of ppm put the switches of its steps and bits at every place between two rows
// in turn, as a generator not clocked with the DAQ does. The default is the DAQ's clock.
struct GeneratorClock {
  double rate_error = 0.0;  // (f_generator − f_nominal) / f_nominal
  double offset_s = 0.0;    // the generator's time at the DAQ's t = 0
};

class AnalogVoltage {
 public:
  // Throws std::invalid_argument naming the field (excitation::validate) on invalid settings, or
  // a clock whose rate error is not within ±1e-3 or whose offset is not a time >= 0.
  explicit AnalogVoltage(const excitation::ExcitationSettings& settings, GeneratorClock clock = {});

  // offset + the sines at t + the steps and PRBS bit in effect at `level_time`, clamped to
  // [0, v_max], both instants read on the generator's clock. at(t, t) is the daemon's
  // Excitation::voltage(t) (right-continuous at a switch); an integrator that cuts its steps at
  // every switch passes a level_time inside the piece, so that the piece's end sees the level
  // before the switch.
  double at(double t, double level_time) const noexcept;
  // The first instant after t where a step or the PRBS switches; +∞ when none does.
  double next_switch_after(double t) const noexcept;

 private:
  double generator_time(double t) const noexcept;

  excitation::ExcitationSettings settings_;
  GeneratorClock clock_;
  // The PRBS alone, as ±amplitude around an offset of its amplitude: the daemon's own sequence
  // and position cache, without re-implementing the LFSR's stepping.
  excitation::Excitation bits_;
};

}  // namespace scp::tools::benchsim

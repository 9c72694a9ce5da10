#pragma once
// An excitation (excitation/excitation_settings.hpp) as a voltage continuous in time, for a bench
// whose source is not a DAC: the sines at every instant, the steps and the PRBS bits switching at
// their own instants rather than at sample instants.

#include "excitation/excitation.hpp"
#include "excitation/excitation_settings.hpp"

namespace scp::tools::benchsim {

class AnalogVoltage {
 public:
  // Throws std::invalid_argument naming the field (excitation::validate) on invalid settings.
  explicit AnalogVoltage(const excitation::ExcitationSettings& settings);

  // offset + the sines at t + the steps and PRBS bit in effect at `level_time`, clamped to
  // [0, v_max]. at(t, t) is the daemon's Excitation::voltage(t) (right-continuous at a switch);
  // an integrator that cuts its steps at every switch passes a level_time inside the piece, so
  // that the piece's end sees the level before the switch.
  double at(double t, double level_time) const noexcept;
  // The first instant after t where a step or the PRBS switches; +∞ when none does.
  double next_switch_after(double t) const noexcept;

 private:
  excitation::ExcitationSettings settings_;
  // The PRBS alone, as ±amplitude around an offset of its amplitude: the daemon's own sequence
  // and position cache, without re-implementing the LFSR's stepping.
  excitation::Excitation bits_;
};

}  // namespace scp::tools::benchsim

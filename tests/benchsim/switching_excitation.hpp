#pragma once
// A voltage that switches between sample instants: the paper's sines, a PRBS of 12.3 ms bits and
// two steps (at 0.25 s, −0.3 V; at 0.7 s, +0.2 V).

#include "excitation/excitation.hpp"

namespace scp::tools::benchsim {

inline excitation::ExcitationSettings switching_excitation() {
  excitation::ExcitationSettings s = excitation::paper_excitation();
  s.prbs.amplitude = 0.5;
  s.prbs.bit_period_s = 0.0123;
  s.steps = {{0.25, -0.3}, {0.7, 0.2}};
  return s;
}

}  // namespace scp::tools::benchsim

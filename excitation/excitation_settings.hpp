#pragma once
// What voltage the daemon applies to identify the plant: a sum of sines, steps and a PRBS on an
// offset, clamped to [0, v_max]. Plain data filled by the daemon's config module.

#include <cstdint>
#include <vector>

namespace scp::excitation {

struct Sine {
  double amplitude = 0.0;     // V
  double frequency_hz = 1.0;  // > 0
  double phase_rad = 0.0;     // amplitude·sin(2π·f·t + phase)
};

// From time_s on (t ≥ time_s), level_v is added to the offset. Steps accumulate: a step back
// down is a second step with a negative level.
struct Step {
  double time_s = 0.0;
  double level_v = 0.0;
};

struct ExcitationSettings {
  double v_max = 3.2;   // V, upper clamp (the lower clamp is 0 V: heating only)
  double offset = 0.0;  // V
  std::vector<Sine> sines;
  std::vector<Step> steps;
  // Pseudo-random binary sequence: ±amplitude, one bit per bit_period_s, from a maximal-length
  // LFSR of `order` bits (period 2^order − 1 bits), deterministic from seed.
  struct Prbs {
    double amplitude = 0;  // V; 0 disables the PRBS
    double bit_period_s = 1.0;
    int order = 7;  // 2..31
    std::uint32_t seed = 1;
  } prbs;
};

// The paper's experiment, Section IV (frequency 6·10⁻³ Hz, not "6.10−3"; see PAPER-NOTES):
// V(t) = 1.6 + 0.4[sin(2π·0.006t − π/2) + sin(2π·0.006t) + sin(2π·0.1t) + sin(2π·0.1t − π/2)],
// so 0 ≤ V ≤ 3.2 V.
ExcitationSettings paper_excitation();

}  // namespace scp::excitation

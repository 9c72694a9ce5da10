#pragma once
// The voltage the daemon applies at loop time t: offset + Σ sines + Σ active steps + PRBS,
// clamped to [0, v_max].

#include <cstdint>

#include "excitation/excitation_settings.hpp"
#include "excitation/lfsr.hpp"

namespace scp::excitation {

class Excitation {
 public:
  // Throws std::invalid_argument naming the field ("excitation.sines[1].frequency_hz must be
  // > 0 ...") on invalid settings. Copies the settings (the only allocation).
  explicit Excitation(const ExcitationSettings& settings);

  // Real-time safe: no allocation, O(#sines + #steps) plus O(1) amortized for the PRBS when t
  // does not decrease between calls (a decrease restarts the LFSR from its seed: correct but
  // O(bits)). Non-finite t gives 0 V. Not thread-safe: the PRBS position is cached (mutable).
  double voltage(double t) const noexcept;

 private:
  double prbs(double t) const noexcept;

  ExcitationSettings settings_;
  mutable Lfsr lfsr_;
  mutable std::int64_t lfsr_bit_index_ = 0;  // index of the bit lfsr_ currently outputs
};

// Throws std::invalid_argument naming the first invalid field, e.g. "excitation.v_max".
void validate(const ExcitationSettings& settings);

}  // namespace scp::excitation

#include "excitation/excitation.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

#include "common/checks.hpp"

namespace scp::excitation {

namespace {

using checks::require;

}  // namespace

ExcitationSettings paper_excitation() {
  constexpr double kHalfPi = std::numbers::pi / 2.0;
  ExcitationSettings s;
  s.v_max = 3.2;
  s.offset = 1.6;
  s.sines = {{0.4, 0.006, -kHalfPi}, {0.4, 0.006, 0.0}, {0.4, 0.1, 0.0}, {0.4, 0.1, -kHalfPi}};
  return s;
}

void validate(const ExcitationSettings& s) {
  require(std::isfinite(s.v_max) && s.v_max >= 0.0, "excitation.v_max", "a finite number >= 0",
          s.v_max, "the largest voltage the actuator may see, e.g. 3.2");
  require(std::isfinite(s.offset), "excitation.offset_v", "a finite number", s.offset,
          "e.g. 1.6 (the paper's mean voltage)");
  for (std::size_t i = 0; i < s.sines.size(); ++i) {
    const Sine& w = s.sines[i];
    const std::string key = "excitation.sines[" + std::to_string(i) + "].";
    require(std::isfinite(w.amplitude), key + "amplitude_v", "a finite number", w.amplitude,
            "volts, e.g. 0.4");
    require(std::isfinite(w.frequency_hz) && w.frequency_hz > 0.0, key + "frequency_hz",
            "a finite number > 0", w.frequency_hz, "hertz, e.g. 0.1 (use offset for a constant)");
    require(std::isfinite(w.phase_rad), key + "phase_rad", "a finite number", w.phase_rad,
            "radians, e.g. -1.5708");
  }
  for (std::size_t i = 0; i < s.steps.size(); ++i) {
    const Step& st = s.steps[i];
    const std::string key = "excitation.steps[" + std::to_string(i) + "].";
    require(std::isfinite(st.time_s) && st.time_s >= 0.0, key + "time_s", "a finite number >= 0",
            st.time_s, "seconds after the loop starts");
    require(std::isfinite(st.level_v), key + "level_v", "a finite number", st.level_v,
            "volts added from time_s on (negative to step down)");
  }
  const ExcitationSettings::Prbs& p = s.prbs;
  require(std::isfinite(p.amplitude) && p.amplitude >= 0.0, "excitation.prbs.amplitude_v",
          "a finite number >= 0", p.amplitude, "volts, 0 disables the PRBS");
  require(std::isfinite(p.bit_period_s) && p.bit_period_s > 0.0, "excitation.prbs.bit_period_s",
          "a finite number > 0", p.bit_period_s, "seconds per bit, e.g. 1");
  require(p.order >= Lfsr::kMinOrder && p.order <= Lfsr::kMaxOrder, "excitation.prbs.order",
          "an integer in [2, 31]", p.order, "the sequence repeats every 2^order - 1 bits");
}

Excitation::Excitation(const ExcitationSettings& settings)
    : settings_((validate(settings), settings)), lfsr_(settings.prbs.order, settings.prbs.seed) {}

double Excitation::prbs(double t) const noexcept {
  const ExcitationSettings::Prbs& p = settings_.prbs;
  // Beyond ~2^62 bits the index would overflow; hold the level there (t ≈ 1e11 years at 1 s).
  const double index_real = std::floor(std::max(0.0, t) / p.bit_period_s);
  const auto index = static_cast<std::int64_t>(std::min(index_real, 4.0e18));
  if (index < lfsr_bit_index_) {
    lfsr_ = Lfsr(p.order, p.seed);
    lfsr_bit_index_ = 0;
  }
  // The sequence is periodic: never advance more than one period.
  const auto period = static_cast<std::int64_t>(lfsr_.period());
  std::int64_t ahead = index - lfsr_bit_index_;
  if (ahead >= period) ahead %= period;
  for (std::int64_t i = 0; i < ahead; ++i) lfsr_.advance();
  lfsr_bit_index_ = index;
  return lfsr_.bit() != 0 ? p.amplitude : -p.amplitude;
}

double Excitation::voltage(double t) const noexcept {
  if (!std::isfinite(t)) return 0.0;
  double v = settings_.offset;
  for (const Sine& w : settings_.sines) {
    v += w.amplitude * std::sin(2.0 * std::numbers::pi * w.frequency_hz * t + w.phase_rad);
  }
  for (const Step& st : settings_.steps) {
    if (t >= st.time_s) v += st.level_v;
  }
  if (settings_.prbs.amplitude > 0.0) v += prbs(t);
  if (!std::isfinite(v)) return 0.0;
  return std::clamp(v, 0.0, settings_.v_max);
}

}  // namespace scp::excitation

#include "tools/benchsim/analog_voltage.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>

namespace scp::tools::benchsim {

namespace {

excitation::ExcitationSettings prbs_only(const excitation::ExcitationSettings& s) {
  excitation::ExcitationSettings bits;
  bits.prbs = s.prbs;
  bits.offset = s.prbs.amplitude;
  bits.v_max = 2.0 * s.prbs.amplitude;
  return bits;
}

GeneratorClock checked(GeneratorClock clock) {
  if (!(std::abs(clock.rate_error) <= 1e-3)) {
    throw std::invalid_argument("the generator clock's rate error must be within ±1000 ppm");
  }
  if (!(std::isfinite(clock.offset_s) && clock.offset_s >= 0.0)) {
    throw std::invalid_argument("the generator clock's offset must be a time >= 0 s");
  }
  return clock;
}

}  // namespace

AnalogVoltage::AnalogVoltage(const excitation::ExcitationSettings& settings, GeneratorClock clock)
    : settings_((excitation::validate(settings), settings)),
      clock_(checked(clock)),
      bits_(prbs_only(settings)) {}

// The DAQ's clock itself gives back t exactly, so the default clock writes the files it always did.
double AnalogVoltage::generator_time(double t) const noexcept {
  return t * (1.0 + clock_.rate_error) + clock_.offset_s;
}

double AnalogVoltage::at(double daq_t, double daq_level_time) const noexcept {
  // The same terms in the same order as Excitation::voltage, so at(t, t) is bit for bit its value.
  const double t = generator_time(daq_t);
  const double level_time = generator_time(daq_level_time);
  double v = settings_.offset;
  for (const excitation::Sine& w : settings_.sines) {
    v += w.amplitude * std::sin(2.0 * std::numbers::pi * w.frequency_hz * t + w.phase_rad);
  }
  for (const excitation::Step& st : settings_.steps) {
    if (level_time >= st.time_s) v += st.level_v;
  }
  const double amplitude = settings_.prbs.amplitude;
  if (amplitude > 0.0) v += bits_.voltage(level_time) - amplitude;
  if (!std::isfinite(v)) return 0.0;
  return std::clamp(v, 0.0, settings_.v_max);
}

double AnalogVoltage::next_switch_after(double daq_t) const noexcept {
  const double t = generator_time(daq_t);
  double next = std::numeric_limits<double>::infinity();
  for (const excitation::Step& st : settings_.steps) {
    if (st.time_s > t) next = std::min(next, st.time_s);
  }
  if (settings_.prbs.amplitude > 0.0) {
    const double bit = settings_.prbs.bit_period_s;
    double edge = (std::floor(std::max(0.0, t) / bit) + 1.0) * bit;
    if (edge <= t) edge += bit;  // t/bit rounded up to a whole number
    next = std::min(next, edge);
  }
  if (!std::isfinite(next)) return next;
  return (next - clock_.offset_s) / (1.0 + clock_.rate_error);
}

}  // namespace scp::tools::benchsim

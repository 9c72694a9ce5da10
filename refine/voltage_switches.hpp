#pragma once
// The switches of a continuous drive (a PRBS, a step on an analog source) read with
// VoltageHold::foh and VoltageShape::smooth: found in the rows, and held from a place in their
// intervals (refine/voltage_timing.hpp chooses which, from T̄).

#include <cstddef>
#include <span>
#include <vector>

#include "refine/fit.hpp"

namespace scp::refine {

// A continuous drive that also switches (a PRBS, a step): neither the chord nor a cubic can follow
// a switch from A to B inside an interval. Both put (A² + AB + B²)/3 over it where the switch gives
// between A² and B², a heat deficit (A − B)²/6 at every switch, up or down, that no θ explains.
// Each interval find_voltage_switches flags becomes a held voltage switched `phase` (0..1) of the
// way through it (voltage_since), and its neighbours keep the chord (the cubic would reach across
// the switch). Each side of the switch goes on at its neighbour's chord (slope_before,
// slope_after): a drive that is moving when it switches (a step on a sine) left flat over the
// interval loses A·V'·Δ² of heat at every switch. Where in its interval a switch fell the rows
// cannot say: 0 is a switch just after the previous sample, 1 one at the row's own instant (a
// generator on the DAQ's clock whose row reads the new level), ½ the mean of one on a clock of its
// own; T̄ can (refine/voltage_timing.hpp, choose_switch_phase). prepare_window calls it after
// add_cubic_midpoints; returns how many rows it made held. In a foh window, a held row is a switch
// (count_voltage_switches).
std::size_t hold_voltage_switches(std::span<WindowSample> window, double phase);
std::size_t count_voltage_switches(std::span<const WindowSample> prepared) noexcept;

// Whether the interval ending at each row holds a switch: its slope above kSwitchSlopeRatio times
// both neighbours' and its step above a floor, the larger of a hundredth of the window's voltage
// range and ten times the step's noise (robustly, from the median second difference). A smooth
// drive sampled well above its bandwidth changes slope by O(Δ·V'') between rows. Row 0 never is.
std::vector<bool> find_voltage_switches(std::span<const WindowSample> window);
inline constexpr double kSwitchSlopeRatio = 4.0;

}  // namespace scp::refine

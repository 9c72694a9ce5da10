#pragma once
// JᵀWJ's upper triangle += α·v vᵀ for a v that is non-zero at a fixed set of slots only, the
// products each residual pass and each sweep of a fitted model make per sample
// (refine/residual_pass.cpp, refine/switch_placement.cpp).

#include <array>
#include <cstddef>
#include <utility>

#include "refine/parameters.hpp"

namespace scp::refine::outer_update {

// The slots where a row of J can be non-zero, ascending: T̄'s row is structurally 0 outside
// θ5, θ6, T̄0 and the ambient's terms, x's outside the ambient's terms (parameters.hpp).
template <bool (*In)(int)>
constexpr auto row_slots() {
  constexpr int n = [] {
    int count = 0;
    for (int s = 0; s < kParams; ++s) count += In(s) ? 1 : 0;
    return count;
  }();
  std::array<int, n> slots{};
  for (int s = 0, i = 0; s < kParams; ++s)
    if (In(s)) slots[static_cast<std::size_t>(i++)] = s;
  return slots;
}
constexpr bool in_x_base(int s) {
  return in_x_output(s) && !is_optional(s);
}
constexpr bool in_tbar_base(int s) {
  return in_tbar_output(s) && !is_optional(s);
}
constexpr bool in_tbar_lagged(int s) {
  return in_tbar_base(s) || s == kSensorLagSlot;
}
// Without the optional slots (PassSettings::extensions, sensor_lag false: their columns are 0),
// with the sensor's lag only, with all of them.
inline constexpr auto kXRowSlots = row_slots<in_x_base>();
inline constexpr auto kTbarRowSlots = row_slots<in_tbar_base>();
inline constexpr auto kTbarRowSlotsLagged = row_slots<in_tbar_lagged>();
inline constexpr auto kXRowSlotsExtended = row_slots<in_x_output>();
inline constexpr auto kTbarRowSlotsExtended = row_slots<in_tbar_output>();
// Every slot but the optional ones, and all of them: where the score s_k can be non-zero.
constexpr bool is_base(int s) {
  return !is_optional(s);
}
constexpr bool is_any(int) {
  return true;
}
inline constexpr auto kBaseSlots = row_slots<is_base>();
inline constexpr auto kAllSlots = row_slots<is_any>();

// Column Slots[B] of JᵀWJ's upper triangle += c·v over rows Slots[0..B]: a fixed-size segment
// where the slots are the leading ones (x's row), else term by term.
template <const auto& Slots, std::size_t B>
[[gnu::always_inline]] inline void add_upper_column(ParamMatrix& h, const ParamVector& v,
                                                    double c) noexcept {
  constexpr int j = Slots[B];
  if constexpr (Slots.back() + 1 == static_cast<int>(Slots.size())) {
    h.col(j).template head<j + 1>() += c * v.template head<j + 1>();
  } else {
    for (std::size_t a = 0; a <= B; ++a) h(Slots[a], j) += c * v[Slots[a]];
  }
}

// JᵀWJ's upper triangle += α·v vᵀ where v is non-zero at `Slots` only: Eigen's
// selfadjointView<Upper>().rankUpdate(v, α) term by term ((α·v_j)·v_i into (i, j), column by
// column, so the same sums), without the structural zeros, which are a sixth of x's row and most
// of T̄'s, and unrolled at compile time: Eigen's loop over dynamic-length columns took a third of
// a pass.
template <const auto& Slots, std::size_t... B>
inline void add_outer_upper(ParamMatrix& h, const ParamVector& v, double alpha,
                            std::index_sequence<B...>) noexcept {
  (add_upper_column<Slots, B>(h, v, alpha * v[Slots[B]]), ...);
}
template <const auto& Slots>
inline void add_outer_upper(ParamMatrix& h, const ParamVector& v, double alpha) noexcept {
  add_outer_upper<Slots>(h, v, alpha, std::make_index_sequence<Slots.size()>{});
}

}  // namespace scp::refine::outer_update

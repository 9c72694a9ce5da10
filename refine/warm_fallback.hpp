#pragma once
// Why a warm refit (refine/warm_start.hpp) gave way to the full staged fit, for the result and the
// protocol (FitResult::warm_fallback).

#include <cstdint>

#include "common/names.hpp"

namespace scp::refine {

enum class WarmFallback : std::uint8_t {
  none,                  // warm: the joint stage from the previous solution converged and passed
  not_requested,         // FitSettings::warm was not set: a cold fit by choice
  settings_changed,      // the previous fit was made with other settings
  not_converged_before,  // the previous fit did not converge
  no_overlap,            // the previous trajectory does not reach this window's first sample
  // The window is over twice the previous fit's: the choices a warm refit keeps (the voltage's
  // interval and switches, `auto`'s extensions) are made again on data they have not seen.
  window_grown,
  not_converged,   // the joint stage did not converge within kWarmIterations
  verdict_failed,  // the verdict on the warm solution failed
  // The model validation found structure the warm solution leaves in a block's residuals: the
  // choices it kept (the voltage's interval, the switches' places, `auto`'s extensions, the
  // sensor's lag held) are made again by the full fit.
  structure_found,
};
inline constexpr NameTable<WarmFallback, 9> kWarmFallbackNames{
    {{WarmFallback::none, "none"},
     {WarmFallback::not_requested, "not_requested"},
     {WarmFallback::settings_changed, "settings_changed"},
     {WarmFallback::not_converged_before, "not_converged_before"},
     {WarmFallback::no_overlap, "no_overlap"},
     {WarmFallback::window_grown, "window_grown"},
     {WarmFallback::not_converged, "not_converged"},
     {WarmFallback::verdict_failed, "verdict_failed"},
     {WarmFallback::structure_found, "structure_found"}}};

constexpr const char* to_text(WarmFallback fallback) noexcept {
  return name_of(kWarmFallbackNames, fallback);
}

}  // namespace scp::refine

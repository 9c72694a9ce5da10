#include "daemon/analysis/refine/best.hpp"

#include <cmath>
#include <cstdio>

namespace scp::daemon::refine {

using scp::refine::BlockReport;
using scp::refine::ValidationBlock;
using scp::refine::ValidationReport;
using scp::refine::ValidationTest;
using scp::refine::Verdict;

namespace {

// What a user can do about a failing test (docs/validation.md names each).
const char* remedy(ValidationTest test) noexcept {
  switch (test) {
    case ValidationTest::kSensorLag:
      return "the temperature sensor lags the temperature (declare refine.nuisance.sensor_lag, "
             "s, or set it to estimate)";
    case ValidationTest::kResistanceTempco:
      return "the heater's resistance changes with temperature (set "
             "refine.extensions.resistance_tempco: auto)";
    case ValidationTest::kStiffnessTempco:
      return "the stiffness changes with temperature (set "
             "refine.extensions.stiffness_softening: auto)";
    case ValidationTest::kCoolingTempco:
      return "the cooling changes with temperature (set refine.extensions.cooling_tempco: auto)";
    case ValidationTest::kAmbientOffset:
    case ValidationTest::kAmbientDrift:
      return "check the ambient (actuator.ambient_c) and let refine.nuisance.ambient_offset and "
             "ambient_drift be estimated";
    case ValidationTest::kDisplacementZero:
      return "let refine.nuisance.x_zero be estimated (or hold it at the sensor's zero)";
    case ValidationTest::kIndependenceX:
    case ValidationTest::kIndependenceT:
    case ValidationTest::kThermalResidual:
      return "the model misses how the output depends on its input: check "
             "refine.voltage_interval and estimator.voltage_hold";
    default:
      return "the residuals are not the sensors' noise: check sensors.noise";
  }
}

std::string block_advice(const char* block, const BlockReport& b, const ValidationReport& r) {
  if (b.verdict == Verdict::kUntested) {
    return std::string(block) +
           " untested (the window is short for its time constant: lengthen refine.window_s)";
  }
  std::string out = std::string(block) + " " + scp::refine::verdict_name(b.verdict) + ": " +
                    scp::refine::test_name(b.decisive);
  const double effect = r.outcome(b.decisive).effect;
  if (std::isfinite(effect)) {
    char text[32];
    std::snprintf(text, sizeof text, " (%.3g)", effect);
    out += text;
  }
  return out + "; " + remedy(b.decisive);
}

}  // namespace

std::string interval_advice(const RefinedView& v) {
  const scp::refine::IntervalEvidence& e = v.voltage_interval_evidence;
  char text[400];
  if (e.contradicted) {
    const char* declared = scp::refine::to_text(v.voltage_interval);
    std::snprintf(text, sizeof text,
                  "the data contradict the declared refine.voltage_interval '%s': T fits the other "
                  "interval better (criterion difference %.3g, at least %.3g decides), and the "
                  "refined θ1..θ4 depend on it; declare the other interval, or set "
                  "refine.voltage_interval: estimate",
                  declared, e.statistic, e.threshold);
    return text;
  }
  std::snprintf(text, sizeof text,
                "the voltage's interval is undetermined: the window cannot tell whether a row's V "
                "drove the interval before or after its sample (criterion difference %.3g, below "
                "%.3g), and the refined θ1..θ4 depend on it (the fit took '%s'); declare "
                "refine.voltage_interval or record a V_since column",
                e.statistic, e.threshold, scp::refine::to_text(v.voltage_interval));
  return text;
}

const char* best_name(Best best) noexcept {
  switch (best) {
    case Best::refined:
      return "refined";
    case Best::paper:
      return "paper";
    default:
      return "none";
  }
}

bool block_passed(const BlockReport& block) noexcept {
  return block.verdict == Verdict::kAdequate || block.verdict == Verdict::kNoiseColored;
}

bool passed(const ValidationReport& report) noexcept {
  return block_passed(report.mechanical) && block_passed(report.thermal);
}

std::string failure_advice(const ValidationReport& report) {
  std::string out;
  for (const ValidationBlock b : {ValidationBlock::kMechanical, ValidationBlock::kThermal}) {
    const BlockReport& block = report.block(b);
    if (block_passed(block)) continue;
    if (!out.empty()) out += "; ";
    out +=
        block_advice(b == ValidationBlock::kMechanical ? "mechanical" : "thermal", block, report);
  }
  return out;
}

Best best_of(const RefinedView* v, double now_t) noexcept {
  if (v == nullptr || !v->valid) return Best::paper;
  if (refined_is_best(*v, now_t) && v->validated && passed(v->validation) && !interval_in_doubt(*v))
    return Best::refined;
  return v->paper_validated && passed(v->paper_validation) ? Best::paper : Best::none;
}

BestChoice best_estimate(const RefinedView* v, double now_t) {
  if (v == nullptr || !v->valid) {
    return {Best::paper, "no refined fit yet: the paper law's prediction is not validated yet"};
  }
  std::string why;
  if (!refined_is_best(*v, now_t)) {
    why = !v->converged                                  ? "the refined fit did not converge"
          : now_t - v->fitted_at_t > 3.0 * v->interval_s ? "the refined fit is older than 3 "
                                                           "refine.interval_s"
                                                         : "the refined σ is not finite";
    // What its validation found often says why (a missing term sends the solver astray), and so
    // does a declared interval the data reject.
    if (v->validated && !passed(v->validation)) why += " (" + failure_advice(v->validation) + ")";
    if (interval_contradicted(*v)) why += " (" + interval_advice(*v) + ")";
  } else if (!v->validated) {
    why = "the refined fit is not validated";
  } else if (!passed(v->validation)) {
    why = "refined " + failure_advice(v->validation);
  } else if (interval_in_doubt(*v)) {
    why = interval_advice(*v);
  } else {
    return {Best::refined, ""};
  }
  if (v->paper_validated && passed(v->paper_validation)) return {Best::paper, why};
  why += v->paper_validated ? "; paper law " + failure_advice(v->paper_validation)
                            : "; the paper law's prediction is not validated (no usable θ̂)";
  return {Best::none, why};
}

}  // namespace scp::daemon::refine

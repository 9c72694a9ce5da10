#pragma once
// What the refined fit (refine/fit.hpp) is told about a real bench and what it reports back about
// it, beyond θ: the voltage's timing relative to the samples, the nuisance terms of a real bench
// (a sensor's zero, the ambient's offset and drift, the temperature sensor's lag), and the model
// extensions a real SCP may need (temperature coefficients of R, k and λ). Plain fixed-size
// structs; the defaults are the fit's behaviour before these terms existed. docs/numerics.md
// describes each term.

#include <cstddef>
#include <cstdint>

#include "common/names.hpp"

namespace scp::refine {

// Which interval of the record a row's voltage was applied over.
enum class VoltageInterval : std::uint8_t {
  // Over the interval before its sample, from WindowSample::voltage_since (or the previous
  // sample) until t: the daemon's own recordings.
  before,
  // From its sample's t until the next sample: a log that writes the command issued at t.
  after,
  // Chosen by the data: the fit is run with each and the one with the lower cost kept
  // (FitResult::voltage_interval says which).
  estimate,
};
inline constexpr NameTable<VoltageInterval, 3> kVoltageIntervalNames{
    {{VoltageInterval::before, "before"},
     {VoltageInterval::after, "after"},
     {VoltageInterval::estimate, "estimate"}}};
const char* to_text(VoltageInterval interval) noexcept;  // kVoltageIntervalNames

// How far the data decided VoltageInterval::estimate (refine/voltage_timing.hpp). `statistic` is
// the thermal stage's Schwarz criterion of the interval not chosen minus the chosen one's, net of
// the price the choice charged `after` (both intervals have the same slots, so this is twice the
// log-likelihood ratio): the interval is `determined` when it is at least `threshold`, the χ²₁
// quantile at 0.99 (the other interval then lies outside the likelihood-ratio confidence set of
// the voltage's one-period shift). Otherwise the window cannot tell the two, and θ1..θ4, whose
// common scale is a sub-millisecond lag between heating and motion, are only as right as the guess.
// When it is not, the fit is made under both intervals (refine/fit.cpp, compare_intervals):
// `theta_shift_sigma` is the largest |θ_i(before) − θ_i(after)| / σ_i over the free θ1..θ4 (the
// parameters a one-period shift can move by tens of per cent), and the two are `equivalent` for
// them when it is at most kEquivalentThetaShift. Every θ's σ then also carries the spread between
// the two fits (FitResult::interval_covariance).
struct IntervalEvidence {
  bool estimated = false;  // chosen by the data (else declared, and determined by declaration)
  bool determined = true;
  double statistic = 0.0;
  double threshold = 0.0;
  bool compared = false;  // both intervals fitted (undetermined, and the chosen fit converged)
  bool equivalent = false;
  double theta_shift_sigma = 0.0;
  // A declared interval weighed as `estimate` would weigh it (FitSettings::check_declared_interval:
  // `determined`, `statistic` and `threshold` are then that weighing's, for the interval the data
  // prefer), and `contradicted` when the data determined the other one: θ1..θ4 are then the
  // declaration's, which the data reject.
  bool checked = false;
  bool contradicted = false;
  // Where the thermal stage's criterion (on T̄ alone) left the interval undetermined, or decided
  // it by less than four thresholds, and both intervals' full fits converged, these weighed it
  // again: where their evidence stands `statistic` is theirs, Schwarz's criterion over x and T̄
  // together (the mechanics follow the heat within milliseconds, so x often tells a one-period
  // shift T̄ cannot), and `thermal_statistic` the thermal stage's.
  bool joint = false;
  double thermal_statistic = 0.0;
  // With `joint`: the two fits were weighed with the sensor's lag held at 0 (each fit's lag a few
  // periods or less: a one-period shift in disguise, refine/fit.cpp's joint_difference).
  bool joint_lag_held = false;
};
// A bias of a quarter σ costs an estimate 3 % of its RMS error and its 2σ interval 1 % coverage.
inline constexpr double kEquivalentThetaShift = 0.25;

// A switch the fit placed in its own interval: its row's t and where it fell (voltage_since).
struct PlacedSwitch {
  double t = 0.0;
  double since = 0.0;
};

// A smooth voltage's switches (refine/voltage_timing.hpp, hold_voltage_switches): how many a
// window has and where in their intervals the fit put them (0: just after the previous sample, 1:
// at the row's own instant).
// `placed`: how many of them the fit then placed each in its own interval, from its residuals
// (refine/switch_placement.hpp), and their phases' RMS standard deviation (in intervals).
struct SwitchPhase {
  std::size_t count = 0;
  double phase = 0.0;
  std::size_t placed = 0;
  double rms_phase_sigma = 0.0;
};

// How a voltage read with a first-order hold (estimator::VoltageHold::foh) varied between the
// rows: linearly (a DAC that ramps from one command to the next) or smoothly (a continuous
// drive sampled at the rows: V² through the cubic of four rows, refine/voltage_timing.hpp).
enum class VoltageShape : std::uint8_t { linear, smooth };
inline constexpr NameTable<VoltageShape, 2> kVoltageShapeNames{
    {{VoltageShape::linear, "linear"}, {VoltageShape::smooth, "smooth"}}};

// One nuisance term: estimated, or held at `value` (its units: FitSettings). The library's
// default holds it at 0 (the paper's model); the daemon estimates the three output terms unless
// its configuration holds them (refine.nuisance.*). What freeing them costs a short window is in
// docs/numerics.md.
struct NuisanceSetting {
  bool fixed = true;
  double value = 0.0;
};

// Sign conventions, chosen so that θ means what the paper means (relative to the true rest
// position and the true ambient; T̄ is recorded relative to the configured ambient):
//   x_measured = x_true + x_zero                                    (m)
//   T̄_measured = lag(T̄_true) + ambient_offset + ambient_drift·(t − t0)   (°C, °C/s)
// where the true ambient is the configured one plus ambient_offset + ambient_drift·(t − t0) (a
// room 1 °C warmer than configured: offset +1), t0 is the window's first sample, and lag() is
// the temperature sensor's first order τs·dy/dt = T̄_true − y (τs = sensor_lag, s, ≥ 0; 0 = no
// lag). The sensor lags the absolute temperature; the lag of the ambient's ramp is the constant
// −drift·τs, which the offset takes.
struct NuisanceSettings {
  NuisanceSetting x_zero;          // m
  NuisanceSetting ambient_offset;  // °C
  NuisanceSetting ambient_drift;   // °C/s
  NuisanceSetting sensor_lag;      // s, ≥ 0
};

// An extension of the paper's model: left out, always in, or kept where an information
// criterion says it earns its place in the window (automatic).
enum class ExtensionMode : std::uint8_t { off, on, automatic };
inline constexpr NameTable<ExtensionMode, 3> kExtensionModeNames{
    {{ExtensionMode::off, "off"}, {ExtensionMode::on, "on"}, {ExtensionMode::automatic, "auto"}}};
const char* to_text(ExtensionMode mode) noexcept;  // kExtensionModeNames

// θ keeps its meaning at T̄ = 0 (the ambient):
//   resistance_tempco   ρ (1/°C): R = R0·(1 + ρT̄), the heating θ6·V²/(1 + ρT̄)
//   stiffness_softening κ (1/°C): k = k0·(1 − κT̄), a force +θ3·κ·T̄·x
//   cooling_tempco      γ (1/°C): λ = λ0·(1 + γT̄), the cooling −θ5·(1 + γT̄)·T̄
// Their coefficients as the model simulator uses them; all 0 is the paper's model.
struct Tempcos {
  double rho = 0.0, kappa = 0.0, gamma = 0.0;
  bool any() const noexcept { return rho != 0.0 || kappa != 0.0 || gamma != 0.0; }
  bool thermal() const noexcept { return rho != 0.0 || gamma != 0.0; }
};

struct ExtensionSettings {
  ExtensionMode resistance_tempco = ExtensionMode::off;
  ExtensionMode stiffness_softening = ExtensionMode::off;
  ExtensionMode cooling_tempco = ExtensionMode::off;
  bool any() const noexcept {
    return resistance_tempco != ExtensionMode::off || stiffness_softening != ExtensionMode::off ||
           cooling_tempco != ExtensionMode::off;
  }
};

// A nuisance term as the fit left it: estimated (with its standard deviation) or held.
struct NuisanceEstimate {
  bool estimated = false;
  double value = 0.0;
  double sigma = 0.0;  // 0 when held
};

struct Nuisance {
  NuisanceEstimate x_zero, ambient_offset, ambient_drift, sensor_lag;
};

enum class InformationCriterion : std::uint8_t { none, bic, yic };
inline constexpr NameTable<InformationCriterion, 3> kInformationCriterionNames{
    {{InformationCriterion::none, "none"},
     {InformationCriterion::bic, "bic"},
     {InformationCriterion::yic, "yic"}}};
const char* to_text(InformationCriterion criterion) noexcept;  // kInformationCriterionNames

// An extension as the fit left it.
struct ExtensionEstimate {
  ExtensionMode mode = ExtensionMode::off;
  bool kept = false;  // in the model θ was fitted with
  double value = 0.0;
  double sigma = 0.0;
  // automatic: the criterion with the extension minus without it, fitted to the same window
  // (negative: the extension earned its place), and which criterion decided; none otherwise.
  double criterion_difference = 0.0;
  InformationCriterion criterion = InformationCriterion::none;
};

struct Extensions {
  ExtensionEstimate resistance_tempco, stiffness_softening, cooling_tempco;
};

// With the heater's current measured (refine/heater_power.hpp): R = V/I regressed on the true T̄,
// R = R0·(1 + ρ·T̄), and the resistance the fit's heating input was scaled by.
struct HeaterResistance {
  bool measured = false;  // the window's measured power drove the thermal block
  double reference_ohm = 0.0;
  double r0_ohm = 0.0, r0_sigma_ohm = 0.0;
  double rho = 0.0, rho_sigma = 0.0;  // 1/°C
};

// The coefficients a fit's model ran with (0 for an extension it did not keep).
inline Tempcos tempcos_of(const Extensions& e) noexcept {
  const auto value = [](const ExtensionEstimate& x) { return x.kept ? x.value : 0.0; };
  return {value(e.resistance_tempco), value(e.stiffness_softening), value(e.cooling_tempco)};
}

}  // namespace scp::refine

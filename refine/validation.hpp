#pragma once
// Model validation of an output-error fit (refine/fit.hpp) from its residuals ε = y − ŷ: does
// what the model leaves look like the sensors' noise, or does it still hold something the model
// should have explained? Per output, as MATLAB's `compare` and `resid` and CONTSID's `residc` judge
// a model, on the dynamics' own time scale. The tests and their levels, the formulas and what was
// measured: docs/validation.md.
//
// Streaming: the fit's final residual pass feeds one sample at a time (O(1) work per sample, no
// allocation); the residuals are kept only as block means, a few per time constant of each block
// (at most ValidationSettings::max_blocks, merged in pairs when a long window would exceed it).
// finish() runs the tests on the block means.
//
// Each test regresses the block means of one residual on candidate regressors after projecting
// off what the fit already explains (the block means of the fit's sensitivities J = ∂ŷ/∂p of the
// free parameters): the increment of an auxiliary regression, a Lagrange-multiplier test of the
// model extended by the candidate. A targeted candidate is the output sensitivity of one missing
// term (the term's forcing carried through the model's own dynamics at θ̂), so the test names
// the term and its coefficient estimates its size to first order.

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "estimator/types.hpp"
#include "refine/block_means.hpp"
#include "refine/matrix_functions.hpp"

namespace scp::refine {

using estimator::Vector2;
using estimator::Vector6;

enum class ValidationTest : std::uint8_t {
  // Mechanical block, on ε_x.
  kWhitenessX,        // Ljung–Box on the block means
  kNoiseRatioX,       // χ² of ε_x against the declared σ_x
  kIndependenceX,     // ε_x against the mechanical input T̄ (lags 0..1 time constant)
  kDisplacementZero,  // ε_x against a constant: the sensor's zero
  kStiffnessTempco,   // ε_x against the sensitivity to k(T̄) = k0(1 − κT̄): a T̄·x force
  kThermalResidual,   // ε_x against ε_T carried through the mechanical block: T̄ drives x wrong
  // Thermal block, on ε_T.
  kWhitenessT,
  kNoiseRatioT,
  kIndependenceT,     // ε_T against the thermal input V² (or power) (lags 0..1 time constant)
  kAmbientOffset,     // ε_T against a constant (given a ramp): the ambient is not as configured
  kAmbientDrift,      // ε_T against time (given a constant): the ambient moves
  kSensorLag,         // ε_T against −dT̄/dt: a first-order lag of the temperature sensor
  kResistanceTempco,  // ε_T against the sensitivity to R = R0(1 + ρT̄): a V²·T̄ forcing
  kCoolingTempco,     // ε_T against the sensitivity to λ = λ0(1 + γT̄): a T̄² forcing
  kNone,
};
inline constexpr int kValidationTests = static_cast<int>(ValidationTest::kNone);

// One text name per test ("whiteness_x", "displacement_zero", ...) for the protocol; "none".
const char* test_name(ValidationTest test) noexcept;

enum class ValidationBlock : std::uint8_t { kMechanical, kThermal };
ValidationBlock block_of(ValidationTest test) noexcept;

// Whiteness and the noise ratio say whether the residual is the declared white noise: their
// failure alone leaves θ̂ consistent and puts σ at risk. Independence and the targeted tests say
// whether the residual depends on what drives the model: θ̂ at risk.
bool is_structure_test(ValidationTest test) noexcept;

enum class Verdict : std::uint8_t {
  kAdequate,      // every test of the block passed
  kNoiseColored,  // whiteness or the noise ratio failed, nothing else: θ̂ fine, σ at risk
  kStructure,     // an independence or targeted test failed: θ̂ at risk
  kUntested,      // the window is too short for the block's time scale to test anything
};
const char* verdict_name(Verdict verdict) noexcept;  // "adequate", "noise_colored", ...

inline constexpr int kMaxJacobianColumns = 24;

struct ValidationSettings {
  // The identified model's time constants (s): the mechanical block's slowest and the thermal
  // one (model_time_constants() computes them from θ̂). They set the block length and the lags.
  double mechanical_time_constant_s = 0.0;
  double thermal_time_constant_s = 0.0;
  // The sensors' white-noise standard deviations the configuration declares (x in m, T̄ in °C);
  // ≤ 0: not declared, no noise-ratio test for that output.
  Vector2 declared_noise = Vector2::Zero();
  // Probability of any false alarm among one block's tests on a white-noise residual; each test
  // runs at the Šidák level for the number performed (docs/validation.md).
  double family_level = 0.01;
  // Block length = time constant / this: short enough to resolve the block's dynamics, long
  // enough that noise correlated over less than a block leaves the block means white.
  int blocks_per_time_constant = 8;
  double whiteness_span = 2.0;     // Ljung–Box lags, in time constants
  double independence_span = 1.0;  // input lags of the independence test, in time constants
  std::size_t max_blocks = 4096;   // per block, before adjacent blocks are merged
  // The number of the fit's free parameters whose sensitivities each sample carries (≤
  // kMaxJacobianColumns); 0: none (the residual is tested without projecting off the fit, which
  // makes every regression test conservative: the paper law's prediction).
  int jacobian_columns = 0;
  // Columns of the sensitivities that belong to parameters the fit held fixed (the daemon's
  // `estimator.known`): not projected off, since the fit did not use them.
  std::array<bool, kMaxJacobianColumns> fixed_columns{};
  // Tests switched off (e.g. a targeted test whose term the fit now estimates; a term whose
  // sensitivity is in the span of J drops out by itself).
  std::array<bool, kValidationTests> disabled{};
  // Relative RMS residual (‖ε‖/‖y − mean y‖) below which the residual holds only the
  // simulation's and the arithmetic's rounding, and no test is meaningful (a noise-free
  // simulation); 0 = off. A block below it is `adequate` whatever its tests say
  // (BlockReport::below_numerical_floor; docs/validation.md).
  double numerical_floor = 1e-6;
};

// One sample of the fit's final pass.
struct ValidationSample {
  double t = 0.0;            // s, increasing
  double x = 0.0;            // measured, m
  double x_model = 0.0;      // simulated
  double tbar = 0.0;         // measured, °C above ambient
  double tbar_model = 0.0;   // simulated
  double thermal_input = 0;  // what drives the thermal block over (t_prev, t]: V² or the power
  // The T̄ the model's mechanical block is driven by (the simulated one, unless the fit drives it
  // by the measured T̄).
  double mechanical_input = 0.0;
  // ∂x̂/∂p and ∂T̄̂/∂p (jacobian_columns values each), or empty when jacobian_columns = 0.
  std::span<const double> jacobian_x;
  std::span<const double> jacobian_tbar;
};

struct TestOutcome {
  bool performed = false;  // enough blocks, and a candidate not already in the fit's span
  double statistic = 0.0;  // F (regression tests), Q (whiteness), Σε²/σ² (noise ratio)
  int dof1 = 0, dof2 = 0;
  double p_value = 1.0;
  double level = 0.0;  // the Šidák level it ran at
  // Regression tests: the AR(1) coefficient of the prewhitening, and the share of the residual's
  // block-mean sum of squares (beyond the fit's sensitivities) the candidates explain.
  double ar1 = 0.0;
  double explained = 0.0;
  bool failed = false;
  // Targeted tests: the missing term's size to first order, in its units: m (displacement zero),
  // 1/°C (κ, ρ, γ), °C (ambient offset), °C/s (ambient drift), s (sensor lag), and for the thermal
  // residual the share of ε_T that reaches x as the model says it would (1: all of x's misfit is
  // the thermal block's). NaN otherwise.
  double effect = std::numeric_limits<double>::quiet_NaN();
};

struct BlockReport {
  Verdict verdict = Verdict::kUntested;
  ValidationTest decisive = ValidationTest::kNone;  // the failing test the verdict names
  double fit_percent = 0.0;  // 100·(1 − ‖y − ŷ‖/‖y − mean y‖), MATLAB compare's NRMSE fit
  double residual_rms = 0.0;  // m or °C
  double noise_ratio = 0.0;   // residual RMS / declared σ (0: not declared)
  double block_s = 0.0;       // block length of the decimated residual (s)
  int blocks = 0;
  double whiteness_lags_s = 0.0;     // Ljung–Box lags, in seconds
  double independence_lags_s = 0.0;  // the independence test's input lags, in seconds
  // ‖ε‖/‖y − mean y‖ < ValidationSettings::numerical_floor: the verdict is `adequate` (decisive
  // none) whatever the tests, whose outcomes stay as computed (`untested` stays untested).
  bool below_numerical_floor = false;
};

struct ValidationReport {
  BlockReport mechanical, thermal;
  std::array<TestOutcome, kValidationTests> tests{};
  std::size_t samples = 0;
  std::size_t skipped = 0;  // samples left out: a value not finite, or t not after the last one

  // Whether either block's residuals show structure the model lacks (θ̂ at risk).
  bool structure_found() const {
    return mechanical.verdict == Verdict::kStructure || thermal.verdict == Verdict::kStructure;
  }
  const BlockReport& block(ValidationBlock b) const {
    return b == ValidationBlock::kMechanical ? mechanical : thermal;
  }
  // A test's outcome; for ValidationTest::kNone (a block no test decided) one never performed.
  const TestOutcome& outcome(ValidationTest t) const {
    static constexpr TestOutcome kNotPerformed{};
    const int i = static_cast<int>(t);
    return i >= 0 && i < kValidationTests ? tests[static_cast<std::size_t>(i)] : kNotPerformed;
  }
};

// The slowest time constant of the mechanical block (1/min |Re λ| of s² + (θ1 + θ2T̄)s + θ3) and
// the thermal one (1/θ5), at a typical T̄ (the window's mean).
struct ModelTimeConstants {
  double mechanical_s = 0.0;
  double thermal_s = 0.0;
};
ModelTimeConstants model_time_constants(const Vector6& theta, double tbar) noexcept;

// The rows of one block's block means (BlockMeans::t0, block_s, indices): for columns a caller
// computes at the same layout.
struct BlockLayout {
  double t0 = 0.0;
  double block_s = 1.0;
  std::vector<long> indices;
};

// The validation of one fit, fed sample by sample.
class ResidualValidator {
 public:
  // θ: the fitted parameters (the targeted candidates are the model's sensitivities at θ).
  ResidualValidator(const Vector6& theta, const ValidationSettings& settings);

  // A sample with a value that is not finite, or whose t is not after the previous one's, is left
  // out (counted in ValidationReport::skipped).
  void add(const ValidationSample& s) noexcept;
  // `thermal_fitted`: block means (at thermal_layout()) of the sensitivities of more parameters
  // the fit estimated than the samples carry (the placed voltage switches' phases,
  // refine/switch_placement.hpp); with any, T̄'s whiteness test projects them and the fit's
  // sensitivities off (Breusch–Godfrey) instead of Ljung–Box's.
  ValidationReport finish(const Eigen::MatrixXd& thermal_fitted = Eigen::MatrixXd()) const;
  BlockLayout thermal_layout() const;

 private:
  void advance_candidates(const ValidationSample& s, double dt) noexcept;

  Vector6 theta_;
  ValidationSettings settings_;
  BlockMeans mechanical_, thermal_;
  std::size_t samples_ = 0, skipped_ = 0;
  double t_first_ = 0.0, t_prev_ = 0.0, tbar_model_prev_ = 0.0;
  // Per output (x, T̄): Σε², and y's sums about its first value (for ‖y − mean y‖).
  std::array<double, 2> rss_{}, y_first_{}, y_sum_{}, y_squares_{};
  // The targeted candidates' filters: R and cooling tempco (first order at θ5), and the
  // stiffness tempco's and the thermal residual's [s, ṡ] (the mechanical block at θ, its damping
  // frozen while it changes by less than kDampingTolerance).
  double s_resistance_ = 0.0, s_cooling_ = 0.0;
  Eigen::Vector2d s_stiffness_ = Eigen::Vector2d::Zero();
  Eigen::Vector2d s_thermal_residual_ = Eigen::Vector2d::Zero();
  double thermal_dt_ = -1.0, thermal_decay_ = 1.0, thermal_gain_ = 0.0;
  double mechanical_dt_ = -1.0, mechanical_damping_ = 0.0;
  ExpPhi mechanical_step_{};
};

}  // namespace scp::refine

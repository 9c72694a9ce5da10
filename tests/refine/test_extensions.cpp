// The model's extensions (FitSettings::extensions, refine/fit_terms.hpp): temperature
// coefficients of the heater's resistance (ρ), the stiffness (κ) and the cooling (γ). The
// simulator and its sensitivities against a second, independent simulator (classical RK4 on the
// whole state, tests/refine/deviation_record.hpp) and against central differences; fits that
// estimate them (`on`) and choose them (`auto`) on its records with N1 noise.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "refine/fit.hpp"
#include "refine/model_simulator.hpp"
#include "refine/parameters.hpp"
#include "refine/sensitivities.hpp"
#include "tests/refine/deviation_record.hpp"
#include "tests/refine/record.hpp"

namespace scp::refine {
namespace {

constexpr double kRho = 0.004, kKappa = 0.003, kGamma = 0.005;  // 1/°C: the cells

test::Deviations one_deviation(int slot) {
  test::Deviations d;
  if (slot == kResistanceTempcoSlot) d.resistance_tempco = kRho;
  if (slot == kStiffnessSofteningSlot) d.stiffness_tempco = kKappa;
  if (slot == kCoolingTempcoSlot) d.cooling_tempco = kGamma;
  return d;
}

Tempcos tempcos(const test::Deviations& d) {
  return {d.resistance_tempco, d.stiffness_tempco, d.cooling_tempco};
}

std::vector<WindowSample> noise_free(const test::Deviations& d, double seconds) {
  return test::deviation_record(test::paper_actuator(), seconds, 1e-3, test::paper_voltage(), d);
}

// max |model − record| relative to max |record|, per output.
Vector2 misfit(std::span<const WindowSample> w, const Tempcos& tc) {
  return test::model_misfit(w, test::theta_of(test::paper_actuator()), tc);
}

TEST(Extensions, TheSimulatorFollowsAnIndependentRk4WithEachCoefficient) {
  for (const int slot : {kResistanceTempcoSlot, kStiffnessSofteningSlot, kCoolingTempcoSlot}) {
    const test::Deviations d = one_deviation(slot);
    const auto w = noise_free(d, 60.0);
    const Vector2 with = misfit(w, tempcos(d)), without = misfit(w, {});
    std::printf("slot %d: with the coefficient %.2e, %.2e; without %.2e, %.2e\n", slot, with[0],
                with[1], without[0], without[1]);
    EXPECT_LT(with.maxCoeff(), 1e-6) << slot;
    EXPECT_GT(without.maxCoeff(), 1e-2) << slot;  // the coefficient matters
  }
}

// ∂x/∂p and ∂T̄/∂p of the extended sensitivities against central differences of the simulation.
TEST(Extensions, SensitivitiesMatchCentralDifferences) {
  const test::Deviations d{
      .resistance_tempco = kRho, .stiffness_tempco = kKappa, .cooling_tempco = kGamma};
  const auto w = noise_free(d, 20.0);
  ParamVector p = param_vector(test::theta_of(test::paper_actuator()), InitialState::Zero());
  p[kResistanceTempcoSlot] = kRho;
  p[kStiffnessSofteningSlot] = kKappa;
  p[kCoolingTempcoSlot] = kGamma;
  SensitivitySimulator sim(theta_of(p), initial_state_of(p), false, tempcos_of(p), true);
  std::vector<ParamVector> dx(w.size()), dt(w.size());
  for (std::size_t k = 0; k < w.size(); ++k) {
    if (k > 0) sim.advance(w[k - 1], w[k]);
    dx[k] = sim.dx();
    dt[k] = sim.dtbar();
  }
  for (const int slot :
       {kCooling, kHeating, kResistanceTempcoSlot, kStiffnessSofteningSlot, kCoolingTempcoSlot}) {
    const double h = 1e-4 * std::max(std::abs(p[slot]), 1e-3);
    std::vector<ModelState> up(w.size()), down(w.size());
    ParamVector q = p;
    q[slot] += h;
    simulate(w, theta_of(q), initial_state_of(q), up, 0.0, tempcos_of(q));
    q[slot] -= 2.0 * h;
    simulate(w, theta_of(q), initial_state_of(q), down, 0.0, tempcos_of(q));
    const Eigen::Vector2d e = test::difference_error(up, down, h, dx, dt, slot);
    std::printf("slot %d: x %.2e, T̄ %.2e relative\n", slot, e[0], e[1]);
    EXPECT_LT(e[0], 1e-4) << slot;
    if (acts_on_tbar(slot)) {
      EXPECT_LT(e[1], 1e-4) << slot;
    }
  }
}

std::vector<WindowSample> noisy(const test::Deviations& d, double seconds, unsigned seed) {
  return test::with_noise(noise_free(d, seconds), {.x = 1e-7, .tbar = 1e-3, .seed = seed});
}

Vector6 start() {
  Vector6 s = test::theta_of(test::paper_actuator());
  s.head<4>() *= 0.8;
  return s;
}

void print(const char* what, const FitResult& r) {
  const Vector6 truth = test::theta_of(test::paper_actuator());
  std::printf("%s: %s, %d passes; θ err/σ", what, r.message, r.evaluations);
  for (int i = 0; i < 6; ++i) std::printf(" %.2f", (r.theta[i] - truth[i]) / r.sigma[i]);
  const ExtensionEstimate* e[] = {&r.extensions.resistance_tempco,
                                  &r.extensions.stiffness_softening, &r.extensions.cooling_tempco};
  for (const ExtensionEstimate* x : e)
    std::printf("; %s kept %d %.3g (σ %.2g) ΔBIC %.3g", to_text(x->mode), x->kept, x->value,
                x->sigma, x->criterion_difference);
  std::printf("\n");
}

void expect_theta_within(const FitResult& r, double sigmas) {
  const Vector6 truth = test::theta_of(test::paper_actuator());
  for (int i = 0; i < 6; ++i)
    EXPECT_LT(std::abs(r.theta[i] - truth[i]), sigmas * r.sigma[i])
        << i << ": " << r.theta[i] / truth[i] - 1.0 << " relative, σ " << r.sigma[i] / truth[i];
}

TEST(Extensions, AResistanceTempcoFittedOnIsRecovered) {
  const auto w = noisy(one_deviation(kResistanceTempcoSlot), 300.0, 11);
  FitSettings s;
  s.extensions.resistance_tempco = ExtensionMode::on;
  const FitResult r = fit(w, start(), s);
  print("ρ on", r);
  ASSERT_TRUE(r.converged) << r.message;
  EXPECT_TRUE(r.extensions.resistance_tempco.kept);
  EXPECT_GT(r.extensions.resistance_tempco.sigma, 0.0);
  EXPECT_NEAR(r.extensions.resistance_tempco.value, kRho,
              4.0 * r.extensions.resistance_tempco.sigma);
  expect_theta_within(r, 4.0);
  EXPECT_TRUE(r.validated);
}

FitSettings all_automatic() {
  FitSettings s;
  s.extensions = {ExtensionMode::automatic, ExtensionMode::automatic, ExtensionMode::automatic};
  return s;
}

// `auto` keeps the extension the data need, with its coefficient, and none that they do not.
TEST(Extensions, AutomaticKeepsWhatTheDataNeedAndNothingElse) {
  for (const int slot : {kResistanceTempcoSlot, kStiffnessSofteningSlot, kCoolingTempcoSlot}) {
    const auto w = noisy(one_deviation(slot), 300.0, 20 + static_cast<unsigned>(slot));
    const FitResult r = fit(w, start(), all_automatic());
    print("auto", r);
    ASSERT_TRUE(r.converged) << slot << ": " << r.message;
    for (const ExtensionSlot& e : kExtensionTable) {
      const ExtensionEstimate& x = r.extensions.*e.estimate;
      EXPECT_EQ(x.mode, ExtensionMode::automatic);
      EXPECT_EQ(x.criterion, InformationCriterion::bic);
      EXPECT_EQ(x.kept, e.slot == slot) << "slot " << e.slot << " in the record of " << slot;
    }
    expect_theta_within(r, 4.0);
  }
}

TEST(Extensions, AutomaticAddsNothingToAPaperActuator) {
  const FitResult r = fit(noisy({}, 300.0, 31), start(), all_automatic());
  print("auto, clean", r);
  ASSERT_TRUE(r.converged) << r.message;
  for (const ExtensionSlot& e : kExtensionTable) {
    EXPECT_FALSE((r.extensions.*e.estimate).kept) << e.slot;
    EXPECT_GT((r.extensions.*e.estimate).criterion_difference, 0.0) << e.slot;
  }
  expect_theta_within(r, 4.0);
}

}  // namespace
}  // namespace scp::refine

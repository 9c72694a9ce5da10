// The temperature sensor's lag (NuisanceSettings::sensor_lag, refine/sensor_lag.hpp): the model's
// T̄ through the lag against a second simulator that integrates the sensor with the plant
// (classical RK4 on [x, ẋ, T, T_sensor], tests/refine/deviation_record.hpp), its sensitivity to τs
// against central differences, and a fit that estimates it on that simulator's record with N1
// noise.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "refine/fit.hpp"
#include "refine/model_simulator.hpp"
#include "refine/sensor_lag.hpp"
#include "tests/refine/deviation_record.hpp"
#include "tests/refine/record.hpp"

namespace scp::refine {
namespace {

constexpr double kLag = 0.3;  // s: the cell

std::vector<WindowSample> lagged_record(double seconds, double lag) {
  return test::deviation_record(test::paper_actuator(), seconds, 1e-3, test::paper_voltage(),
                                {.sensor_lag = lag});
}

// The model's T̄ at each sample through a SensorLag of `tau`.
std::vector<double> read_through(std::span<const WindowSample> w, double tau) {
  std::vector<ModelState> model(w.size());
  simulate(w, test::theta_of(test::paper_actuator()), InitialState::Zero(), model);
  SensorLag lag(tau);
  lag.start(model[0].tbar, nullptr);
  std::vector<double> out{model[0].tbar};
  for (std::size_t k = 1; k < w.size(); ++k)
    out.push_back(lag.advance(w[k].t - w[k - 1].t, model[k].tbar, nullptr));
  return out;
}

TEST(SensorLag, TheLaggedModelFollowsASensorIntegratedWithThePlant) {
  const auto w = lagged_record(60.0, kLag);
  const std::vector<double> with = read_through(w, kLag), without = read_through(w, 0.0);
  double e_with = 0.0, e_without = 0.0, top = 0.0;
  for (std::size_t k = 0; k < w.size(); ++k) {
    e_with = std::max(e_with, std::abs(with[k] - w[k].tbar));
    e_without = std::max(e_without, std::abs(without[k] - w[k].tbar));
    top = std::max(top, std::abs(w[k].tbar));
  }
  std::printf("max |reading − RK4 sensor| / max T̄: with the lag %.2e, without %.2e\n", e_with / top,
              e_without / top);
  EXPECT_LT(e_with, 1e-6 * top);
  EXPECT_GT(e_without, 1e-3 * top);  // the lag matters
}

// ∂y/∂τs against central differences, at τs = 0.3 s and at 0 (the continuation's slope).
TEST(SensorLag, ItsSensitivityMatchesCentralDifferences) {
  const auto w = lagged_record(20.0, kLag);
  std::vector<ModelState> model(w.size());
  simulate(w, test::theta_of(test::paper_actuator()), InitialState::Zero(), model);
  for (const double tau : {kLag, 0.0}) {
    SensorLag lag(tau);
    const ParamVector zero = ParamVector::Zero();
    lag.start(model[0].tbar, &zero);
    const double h = 1e-6;
    const std::vector<double> up = read_through(w, tau + h), down = read_through(w, tau - h);
    double err = 0.0, top = 0.0;
    for (std::size_t k = 1; k < w.size(); ++k) {
      lag.advance(w[k].t - w[k - 1].t, model[k].tbar, &zero);
      const double fd = (up[k] - down[k]) / (2.0 * h);
      err = std::max(err, std::abs(lag.sensitivities()[kSensorLagSlot] - fd));
      top = std::max(top, std::abs(fd));
    }
    std::printf("τs %.1f: ∂y/∂τs within %.2e of central differences (max %.3g °C/s)\n", tau,
                err / top, top);
    EXPECT_LT(err, 1e-5 * top) << tau;
  }
}

TEST(SensorLag, AnEstimatedLagIsRecoveredAndThetaStaysWithinItsSigma) {
  const auto w =
      test::with_noise(lagged_record(300.0, kLag), {.x = 1e-7, .tbar = 1e-3, .seed = 41});
  FitSettings s;
  s.nuisance.sensor_lag.fixed = false;
  Vector6 start = test::theta_of(test::paper_actuator());
  start.head<4>() *= 0.8;
  const FitResult r = fit(w, start, s);
  const Vector6 truth = test::theta_of(test::paper_actuator());
  std::printf("%s, %d passes; lag %.5f s (σ %.2g); θ err/σ", r.message, r.evaluations,
              r.nuisance.sensor_lag.value, r.nuisance.sensor_lag.sigma);
  for (int i = 0; i < 6; ++i) std::printf(" %.2f", (r.theta[i] - truth[i]) / r.sigma[i]);
  std::printf("\n");
  ASSERT_TRUE(r.converged) << r.message;
  EXPECT_TRUE(r.nuisance.sensor_lag.estimated);
  EXPECT_GT(r.nuisance.sensor_lag.sigma, 0.0);
  EXPECT_NEAR(r.nuisance.sensor_lag.value, kLag, 4.0 * r.nuisance.sensor_lag.sigma);
  for (int i = 0; i < 6; ++i) EXPECT_LT(std::abs(r.theta[i] - truth[i]), 4.0 * r.sigma[i]) << i;
}

// Beside an estimated delay (refine/lag_hold.hpp: the lag judged with the delay), a
// thermocouple's lag, far longer than any delay the search allows, is still estimated.
TEST(SensorLag, ARealLagIsEstimatedBesideTheVoltagesDelay) {
  const auto w =
      test::with_noise(lagged_record(120.0, kLag), {.x = 1e-7, .tbar = 1e-3, .seed = 43});
  FitSettings s;
  s.max_input_delay_s = 5e-3;
  for (NuisanceSetting* term : {&s.nuisance.x_zero, &s.nuisance.ambient_offset,
                                &s.nuisance.ambient_drift, &s.nuisance.sensor_lag})
    term->fixed = false;
  const FitResult r = fit(w, test::theta_of(test::paper_actuator()), s);
  const Vector6 truth = test::theta_of(test::paper_actuator());
  std::printf("%s; lag %.5f s (σ %.2g)%s; delay %.2f µs (σ %.2g µs); θ err/σ", r.message,
              r.nuisance.sensor_lag.value, r.nuisance.sensor_lag.sigma,
              r.sensor_lag_held ? " held" : "", r.input_delay_s * 1e6, r.input_delay_sigma_s * 1e6);
  for (int i = 0; i < 6; ++i) std::printf(" %.2f", (r.theta[i] - truth[i]) / r.sigma[i]);
  std::printf("\n");
  ASSERT_TRUE(r.converged) << r.message;
  EXPECT_FALSE(r.sensor_lag_held);
  EXPECT_NEAR(r.nuisance.sensor_lag.value, kLag, 4.0 * r.nuisance.sensor_lag.sigma);
  EXPECT_NEAR(r.input_delay_s, 0.0, 4.0 * r.input_delay_sigma_s);
  for (int i = 0; i < 6; ++i) EXPECT_LT(std::abs(r.theta[i] - truth[i]), 4.0 * r.sigma[i]) << i;
}

// A window short against the excitation's slow period cannot tell a lag from T̄0, the ambient's
// terms and θ5 (refine/lag_hold.hpp): without one the fit holds it at 0 there and estimates it
// once the window separates it; a real lag shows in the short window too and is estimated.
FitResult fit_lag_free(double seconds, double lag, unsigned seed) {
  const auto w =
      test::with_noise(lagged_record(seconds, lag), {.x = 1e-7, .tbar = 1e-3, .seed = seed});
  FitSettings s;
  for (NuisanceSetting* term : {&s.nuisance.x_zero, &s.nuisance.ambient_offset,
                                &s.nuisance.ambient_drift, &s.nuisance.sensor_lag})
    term->fixed = false;
  return fit(w, test::theta_of(test::paper_actuator()), s);
}

TEST(SensorLag, AShortWindowHoldsALagItCannotDetermineAndEstimatesOneItCan) {
  const FitResult short_clean = fit_lag_free(40.0, 0.0, 43);
  std::printf("40 s without a lag: %s, %d passes, held %d\n", short_clean.message,
              short_clean.evaluations, short_clean.sensor_lag_held);
  ASSERT_TRUE(short_clean.converged) << short_clean.message;
  EXPECT_TRUE(short_clean.sensor_lag_held);
  EXPECT_FALSE(short_clean.nuisance.sensor_lag.estimated);
  EXPECT_EQ(short_clean.nuisance.sensor_lag.value, 0.0);

  const FitResult short_lagged = fit_lag_free(40.0, kLag, 43);
  std::printf("40 s with a %.1f s lag: %s, %d passes, lag %.5f (σ %.2g)\n", kLag,
              short_lagged.message, short_lagged.evaluations,
              short_lagged.nuisance.sensor_lag.value, short_lagged.nuisance.sensor_lag.sigma);
  ASSERT_TRUE(short_lagged.converged) << short_lagged.message;
  EXPECT_FALSE(short_lagged.sensor_lag_held);
  EXPECT_TRUE(short_lagged.nuisance.sensor_lag.estimated);
  EXPECT_NEAR(short_lagged.nuisance.sensor_lag.value, kLag,
              4.0 * short_lagged.nuisance.sensor_lag.sigma);

  const FitResult long_clean = fit_lag_free(120.0, 0.0, 43);
  std::printf("120 s without a lag: %s, %d passes, lag %.3g (σ %.2g)\n", long_clean.message,
              long_clean.evaluations, long_clean.nuisance.sensor_lag.value,
              long_clean.nuisance.sensor_lag.sigma);
  ASSERT_TRUE(long_clean.converged) << long_clean.message;
  EXPECT_FALSE(long_clean.sensor_lag_held);
  EXPECT_TRUE(long_clean.nuisance.sensor_lag.estimated);
  EXPECT_LT(std::abs(long_clean.nuisance.sensor_lag.value),
            4.0 * long_clean.nuisance.sensor_lag.sigma);
}

}  // namespace
}  // namespace scp::refine

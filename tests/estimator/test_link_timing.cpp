// The estimator on a real link's timing (issue 8, part 7), with the independent RK4 plant: at a
// 10 ms period the sample is taken 1-3 ms after the cycle's deadline (jitter) and the new voltage
// reaches the plant 2-5 ms after the sample, not at a sample instant. Fed the instants the samples
// were really taken and Measurement::voltage_since, the paper law must do as well as on an ideal
// DAC; fed the deadlines (what the daemon did before), it must not — or this test proves nothing.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "estimator/estimator.hpp"
#include "tests/estimator/test_plant.hpp"

namespace scp::estimator {
namespace {

constexpr double kH = 0.01;  // 100 Hz, the Modbus RTU period of docs/driver-modbus.md
constexpr int kSubstepsPerMs = 20;

Vector6 true_theta() {  // Table I by hand
  Vector6 t;
  t << 124.7 / 0.1, 0.08 / 0.1, 181.3 / 0.1, 0.01 / 0.1, 0.0540 / 0.9090, 1.0 / 0.9090;
  return t;
}

EstimatorConfig config_100hz() {  // the paper's gains, as tests/e2e_drivers runs them
  EstimatorConfig c;
  c.p_max = 1e20;
  c.nominal_period = kH;
  return c;
}

struct LinkRun {
  Estimator stamped{config_100hz()};   // real sample instants and voltage_since
  Estimator deadline{config_100hz()};  // the cycle's deadlines, voltage switching at samples
  Estimator ideal{config_100hz()};     // an ideal DAC: samples at deadlines, switching at them
};

void step_plant(test::Plant& p, double dt, double v) {
  if (dt <= 0) return;
  p.advance(dt, v, std::max(1, static_cast<int>(std::ceil(dt * 1e3 * kSubstepsPerMs))));
}

double max_rel(const Vector6& theta_hat, int first, int n) {
  const Vector6 t = true_theta();
  double m = 0;
  for (int i = first; i < first + n; ++i) m = std::max(m, std::abs(theta_hat(i) - t(i)) / t(i));
  return m;
}

// Runs `seconds` of the paper's experiment over the jittery link, and the same excitation on an
// ideal DAC, feeding the three estimators.
void run(LinkRun& r, double seconds, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> sample_delay(0.001, 0.003);  // read lands after deadline
  std::uniform_real_distribution<double> write_delay(0.002, 0.005);   // write lands after sample
  test::Plant link_plant, ideal_plant;
  double t_plant = 0.0, v_applied = 0.0;
  double v_cmd = 0.0, since = -INFINITY;
  const auto n = static_cast<long>(std::llround(seconds / kH));
  for (long k = 0; k <= n; ++k) {
    const double deadline = static_cast<double>(k) * kH;
    // The link: the read samples at deadline + d, the command computed from it lands w later.
    const double t_sample = deadline + sample_delay(rng);
    step_plant(link_plant, t_sample - t_plant, v_applied);
    t_plant = t_sample;
    const Measurement m{t_sample, link_plant.x, link_plant.xdot, link_plant.tbar, v_cmd, since};
    r.stamped.update(m);
    Measurement at_deadline = m;
    at_deadline.t = deadline;
    at_deadline.voltage_since = -INFINITY;
    r.deadline.update(at_deadline);
    v_cmd = test::paper_voltage(deadline);
    const double t_write = t_sample + write_delay(rng);
    step_plant(link_plant, t_write - t_plant, v_applied);
    t_plant = t_write;
    v_applied = v_cmd;
    since = t_write;

    // The ideal DAC: sample and switch exactly at the deadline.
    if (k > 0) step_plant(ideal_plant, kH, test::paper_voltage(deadline - kH));
    r.ideal.update(Measurement{deadline, ideal_plant.x, ideal_plant.xdot, ideal_plant.tbar,
                               k > 0 ? test::paper_voltage(deadline - kH) : 0.0});
  }
}

TEST(EstimatorLinkTiming, StampedSamplesAndVoltageSinceMatchAnIdealDac) {
  LinkRun r;
  run(r, 200.0, 8);
  const Vector6 s = r.stamped.estimate().theta_hat, d = r.deadline.estimate().theta_hat,
                i = r.ideal.estimate().theta_hat;
  std::printf(
      "[measured] 100 Hz, 200 s, max rel. error theta1..4 / theta5,6: ideal DAC %.2e / %.2e, "
      "stamped %.2e / %.2e, deadlines %.2e / %.2e\n",
      max_rel(i, 0, 4), max_rel(i, 4, 2), max_rel(s, 0, 4), max_rel(s, 4, 2), max_rel(d, 0, 4),
      max_rel(d, 4, 2));
  // θ5, θ6: exact filters give ~1e-13 either way. Deadlines misplace V² by the 3-8 ms between
  // the sample and the write landing: measured 4-7e-4 over 600 s (the bench: 7.6e-4 at
  // 60 s). Stamped, T̄ follows the held lag with its kink where the write landed (held_lag.hpp):
  // measured 1e-13 (the quadratic lag without the kink left 4-7e-6).
  EXPECT_LT(max_rel(s, 4, 2), 1e-10);
  EXPECT_GT(max_rel(d, 4, 2), 1e-4);
  // θ1..θ4 at 100 Hz: what is left is the 3-point quadratic through ẋ, which has a kink at each
  // switch too (the fast mechanical pole bends it within ~1 ms): 7-9e-3 on the ideal DAC over
  // 200-600 s, 3.6-6.7e-3 stamped (seeds 1, 2, 3, 8; before T̄'s kink was modelled, stamped
  // was 1.5-2.2e-2). The target for the paper law on a 10 ms link is 1e-2.
  EXPECT_LT(max_rel(s, 0, 4), 1e-2);
  EXPECT_LT(max_rel(i, 0, 4), 1.5e-2);
  EXPECT_EQ(r.stamped.estimate().skipped_time, 0U);
  EXPECT_EQ(r.stamped.estimate().filter_restarts, 0U);
}

// voltage_since at or before the previous sample (or −∞, the default) is a DAC switching at
// sample instants: the estimator must do exactly what it did before the field existed.
TEST(EstimatorLinkTiming, VoltageSinceBeforeTheIntervalChangesNothing) {
  Estimator by_default(config_100hz()), explicit_prev(config_100hz());
  test::Plant plant;
  double v_prev = 0.0;
  for (int k = 0; k <= 3000; ++k) {
    const double t = k * kH;
    if (k > 0) step_plant(plant, kH, v_prev);
    const Measurement m{t, plant.x, plant.xdot, plant.tbar, v_prev};
    Measurement at_prev = m;
    at_prev.voltage_since = (k > 0 ? k - 1 : k) * kH;  // the previous sample's instant
    by_default.update(m);
    explicit_prev.update(at_prev);
    v_prev = test::paper_voltage(t);
  }
  for (int i = 0; i < 6; ++i) {
    EXPECT_EQ(by_default.estimate().theta_hat(i), explicit_prev.estimate().theta_hat(i));
  }
}

}  // namespace
}  // namespace scp::estimator

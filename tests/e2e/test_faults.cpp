// Issues 3 and 5: sensor faults forced in the simulator, as an operator sees them on the socket.
// Every fault must put the output at 0 V in the same cycle, show FAULT with the right reason,
// keep the learned estimate, and leave the daemon answering.

#include <chrono>
#include <ostream>

#include "tests/e2e/e2e_util.hpp"

namespace scp::test {
namespace {

// Polls `status` on one connection as fast as the daemon answers, until loop time `until_s`.
std::vector<json> observe_until(const DaemonProcess& daemon, double until_s,
                                double wall_limit_s = 15) {
  std::vector<json> seen;
  Client c = daemon.connect();
  const auto end = std::chrono::steady_clock::now() + Seconds(wall_limit_s);
  while (std::chrono::steady_clock::now() < end) {
    seen.push_back(c.request({{"request", "status"}}));
    if (num(seen.back(), "uptime_s", 0.0) >= until_s) break;
  }
  return seen;
}

// True when the published reading itself is one the safety layer must refuse. The snapshot holds
// the reading and the command of the same cycle, so such a snapshot must already show 0 V.
bool reading_is_bad(const json& status, double temperature_max) {
  const json& s = status.at("sample");
  if (!s.contains("x") || !s.contains("temperature")) return true;  // non-finite: omitted
  return s["temperature"].get<double>() > temperature_max;
}

// Checks the invariants over every observed snapshot; returns the first one in FAULT.
std::optional<json> check_zero_volt_invariant(const std::vector<json>& seen,
                                              double temperature_max) {
  std::optional<json> first_fault;
  int bad_readings = 0;
  for (const json& s : seen) {
    const std::string state = s.value("state", "");
    if (state == "starting") {
      // Before the first fresh reading there is no sample to judge (on a loaded machine the
      // first polls can come before it); the start-up rule is 0 V.
      EXPECT_EQ(num(s, "voltage"), 0.0) << "output before fresh readings: " << s.dump();
      continue;
    }
    if (state == "fault") {
      EXPECT_EQ(num(s, "voltage"), 0.0) << "FAULT but the output is not at 0 V: " << s.dump();
      if (!first_fault) first_fault = s;
    }
    if (reading_is_bad(s, temperature_max)) {
      ++bad_readings;
      EXPECT_EQ(state, "fault") << "a bad reading was published without FAULT: " << s.dump();
      EXPECT_EQ(num(s, "voltage"), 0.0) << "bad reading, output not at 0 V: " << s.dump();
    }
  }
  return first_fault;
}

// Issue 3, item 4: NaN temperature for 1.5 s. The operator sees FAULT with the reason and 0 V;
// `clear-fault` is refused while the sensor is still bad (socket and scp-estimatorctl), and
// accepted once it reads again, after which the output resumes.
TEST(Faults, SensorFaultLatchesAndClearFaultWaitsForTheCause) {
  TempDir dir;
  DaemonProcess daemon(
      dir,
      {{"driver",
        {{"sim",
          {{"fault", {{"kind", "nan_temperature"}, {"start_s", 1.5}, {"duration_s", 1.5}}}}}}}});
  daemon.start();
  const json before = daemon.estimate();
  const auto seen = observe_until(daemon, 2.0);
  const auto first_fault = check_zero_volt_invariant(seen, 150.0);
  ASSERT_TRUE(first_fault) << "no FAULT seen by loop time 2 s";
  EXPECT_TRUE(
      contains(first_fault->value("fault_reason", ""), "temperature is not a finite number"))
      << first_fault->dump();
  EXPECT_GE(num(*first_fault, "uptime_s"), 1.5 - 1e-9) << "fault before it was injected";

  // The cause persists: refused, with the cause in the message.
  Client c = daemon.connect();
  const json refused = c.request({{"request", "clear-fault"}});
  EXPECT_EQ(refused.value("class", ""), "ACK") << refused.dump();
  EXPECT_FALSE(refused.value("ok", true)) << refused.dump();
  EXPECT_TRUE(contains(refused.value("message", ""), "temperature")) << refused.dump();
  const ProcessResult ctl_refused = daemon.run_ctl({"clear-fault"});
  EXPECT_EQ(ctl_refused.exit_code, 1) << ctl_refused.out << ctl_refused.err;
  ASSERT_LT(num(daemon.status(), "uptime_s"), 3.0) << "machine too slow: the fault already ended";

  // The sensor recovers at 3 s, but a value fault latches until an operator clears it.
  const auto rest = observe_until(daemon, 3.3);
  check_zero_volt_invariant(rest, 150.0);
  const json latched = daemon.status();
  EXPECT_EQ(latched.value("state", ""), "fault") << latched.dump();
  EXPECT_EQ(num(latched, "voltage"), 0.0);

  const ProcessResult cleared = daemon.run_ctl({"clear-fault"});
  EXPECT_EQ(cleared.exit_code, 0) << cleared.out << cleared.err;
  const auto running = daemon.wait_status(
      [](const json& s) { return s.value("state", "") == "running" && num(s, "voltage") > 0.0; },
      Seconds(3));
  EXPECT_TRUE(running) << "not RUNNING with output after clear-fault: " << daemon.status().dump();
  // No lost state: the estimator kept its samples through the fault.
  const json after = daemon.estimate();
  EXPECT_GT(after.value("updates", 0ULL), before.value("updates", 0ULL));
  EXPECT_TRUE(daemon.running());
}

struct ValueFault {
  const char* kind;
  const char* reason;  // part of the fault_reason the operator must see
};

// Keeps the ctest names readable ("GetParam() = nan_temperature" instead of raw bytes).
void PrintTo(const ValueFault& f, std::ostream* os) {
  *os << f.kind;
}

class ValueFaults : public ::testing::TestWithParam<ValueFault> {};

// Issue 5: NaN, infinite, out-of-range and stuck readings. Each: FAULT with its reason, 0 V in
// the cycle of the bad reading, latched after the sensor recovers, estimate kept, daemon alive.
TEST_P(ValueFaults, ZeroVoltFaultWithReason) {
  const ValueFault f = GetParam();
  TempDir dir;
  DaemonProcess daemon(
      dir, {{"driver",
             {{"sim", {{"fault", {{"kind", f.kind}, {"start_s", 1.0}, {"duration_s", 1.0}}}}}}},
            {"safety", {{"stuck_timeout_s", 0.2}}}});
  daemon.start();
  sleep_s(0.5);
  const json before = daemon.estimate();
  const auto seen = observe_until(daemon, 2.3);
  const auto first_fault = check_zero_volt_invariant(seen, 150.0);
  ASSERT_TRUE(first_fault) << f.kind << ": no FAULT seen";
  EXPECT_TRUE(contains(first_fault->value("fault_reason", ""), f.reason))
      << f.kind << ": " << first_fault->dump();
  EXPECT_GE(num(*first_fault, "uptime_s"), 1.0 - 1e-9);
  if (std::string(f.kind) == "stuck_sensor") {
    // Detected after stuck_timeout_s, not before.
    EXPECT_GE(num(*first_fault, "uptime_s"), 1.0 + 0.2 - 0.002) << first_fault->dump();
  }
  const json after = daemon.status();
  EXPECT_EQ(after.value("state", ""), "fault") << "a value fault must latch: " << after.dump();
  EXPECT_EQ(num(after, "voltage"), 0.0);
  const json estimate = daemon.estimate();
  EXPECT_GE(estimate.value("updates", 0ULL), before.value("updates", 0ULL)) << "estimate lost";
  for (std::size_t i = 0; i < 6; ++i) EXPECT_TRUE(estimate["theta_hat"][i].is_number());
  EXPECT_TRUE(daemon.running());
}

INSTANTIATE_TEST_SUITE_P(
    Sim, ValueFaults,
    ::testing::Values(ValueFault{"nan_temperature", "temperature is not a finite number"},
                      ValueFault{"inf_position", "position x is not a finite number"},
                      ValueFault{"temperature_out_of_range", "above safety.temperature_max_c"},
                      ValueFault{"stuck_sensor", "sensor stuck: x and T unchanged"}),
    [](const ::testing::TestParamInfo<ValueFault>& p) { return std::string(p.param.kind); });

// Issue 5: a driver that fails in a burst (0.2 s of read errors). It is a driver fault: 0 V and
// FAULT with the driver's message, then RUNNING again by itself after safety.recover_after_s of
// good readings, without anyone sending clear-fault.
TEST(Faults, ReadErrorBurstRecoversByItself) {
  TempDir dir;
  DaemonProcess daemon(
      dir,
      {{"driver",
        {{"sim", {{"fault", {{"kind", "read_error"}, {"start_s", 1.0}, {"duration_s", 0.2}}}}}}},
       {"safety", {{"recover_after_s", 0.5}}}});
  daemon.start();
  const auto seen = observe_until(daemon, 1.15);
  const auto first_fault = check_zero_volt_invariant(seen, 150.0);
  ASSERT_TRUE(first_fault) << "no FAULT during the read-error burst";
  EXPECT_TRUE(contains(first_fault->value("fault_reason", ""), "simulated sensor read error"))
      << first_fault->dump();
  const json st = daemon.status();
  EXPECT_GT(st.at("driver_stats").value("read_errors", 0), 0) << st.dump();
  // Recovery: RUNNING with the output back, not before 1.2 + 0.5 s of loop time.
  const auto back = daemon.wait_status(
      [](const json& s) { return s.value("state", "") == "running" && num(s, "voltage") > 0.0; },
      Seconds(5));
  ASSERT_TRUE(back) << "did not recover by itself: " << daemon.status().dump();
  EXPECT_GE(num(*back, "uptime_s"), 1.2 + 0.5 - 0.01) << back->dump();
  EXPECT_FALSE(back->contains("fault_reason")) << back->dump();
}

}  // namespace
}  // namespace scp::test

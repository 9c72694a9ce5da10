// Experiment design (issue 8, part 8; docs/montecarlo.md "Experiment design per actuator"): every
// actuator of scripts/montecarlo runs an experiment whose Cramér–Rao bound is within the issue's
// limits, so that no limit asks more than an efficient estimator can give. The paper's four-sine
// voltage does this for the paper's and the heavy-slow actuator but not for light-stiff (stiff,
// light, τ = 5 s), which therefore has its own excitation; a regression to the paper's voltage
// there fails the first test.

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <string>

#include "daemon/config/binder.hpp"
#include "daemon/config/daemon_config.hpp"
#include "tools/crb/crb_report.hpp"
#include "tools/crb/experiment.hpp"

namespace {

using scp::tools::crb::NoiseLevel;

const std::string kSource = SCP_SOURCE_DIR;

struct Limits {
  const char* name;
  NoiseLevel noise;   // what the bound sees of issue 8's level: x and T (ẋ is not fitted)
  double mechanical;  // θ1..θ4, relative
  double thermal;     // θ5, θ6, relative
};

// Issue 8, "Done when", per noise level.
constexpr Limits kLevels[] = {{"N1", {1e-7, 1e-3}, 0.01, 1e-5},
                              {"N2", {1e-6, 1e-2}, 0.10, 1e-4},
                              {"N3", {1e-6, 0.1}, 0.10, 1e-4}};

// The worst relative bound of θ1..θ4 and of θ5, θ6 of `config` over 300 s at its own loop rate,
// per level; peak temperature checked against the config's own limit.
void expect_within_limits(const scp::config::DaemonConfig& cfg, const std::string& label) {
  const auto e = scp::tools::crb::simulate(cfg, 300.0, 300.0);
  for (const Limits& level : kLevels) {
    const auto r = scp::tools::crb::crb_report(e, level.noise, {}, cfg.actuator.ambient_c,
                                               cfg.safety.temperature_max_c);
    double mech = 0.0;
    double therm = 0.0;
    for (int i = 0; i < 4; ++i) mech = std::max(mech, r["crb_rel"][i].get<double>());
    for (int i = 4; i < 6; ++i) therm = std::max(therm, r["crb_rel"][i].get<double>());
    std::printf("%s %s: CRB theta1..4 %.3g (limit %.3g), theta5,6 %.3g (limit %.3g), peak %.1f C\n",
                label.c_str(), level.name, mech, level.mechanical, therm, level.thermal,
                r["thermal"]["max_temperature_c"].get<double>());
    EXPECT_LE(mech, level.mechanical) << label << " " << level.name;
    EXPECT_LE(therm, level.thermal) << label << " " << level.name;
    EXPECT_TRUE(r["thermal"]["within_limit"].get<bool>()) << label;
  }
}

TEST(ExperimentDesign, LightStiffsOwnExcitationBoundsThetaWithinTheIssuesLimits) {
  expect_within_limits(
      scp::config::load_config_file(kSource + "/config/actuators/light-stiff.yaml"), "light-stiff");
}

TEST(ExperimentDesign, ThePaperActuatorAndHeavySlowMeetTheLimitsWithThePapersVoltage) {
  const auto paper = scp::config::load_config_file(kSource + "/config/paper.yaml");
  EXPECT_EQ(paper.excitation.profile, scp::config::ExcitationProfile::paper);
  expect_within_limits(paper, "paper");
  const auto heavy = scp::config::load_config_file(kSource + "/config/actuators/heavy-slow.yaml");
  EXPECT_EQ(heavy.excitation.profile, scp::config::ExcitationProfile::paper);
  expect_within_limits(heavy, "heavy-slow");
}

// Why light-stiff needs its own voltage: under the paper's, its θ1..θ4 bound is 4.4 % at N1 and
// 44 % at N2 (measured), above the limits whatever the estimator.
TEST(ExperimentDesign, ThePapersVoltageDoesNotIdentifyLightStiff) {
  auto cfg = scp::config::load_config_file(kSource + "/config/actuators/light-stiff.yaml");
  cfg.excitation = scp::config::load_config_file(kSource + "/config/paper.yaml").excitation;
  const auto e = scp::tools::crb::simulate(cfg, 300.0, 300.0);
  const auto r = scp::tools::crb::crb_report(e, kLevels[0].noise, {}, cfg.actuator.ambient_c,
                                             cfg.safety.temperature_max_c);
  for (int i = 0; i < 4; ++i) EXPECT_GT(r["crb_rel"][i].get<double>(), 0.03) << "theta" << i + 1;
}

}  // namespace

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>

#include "daemon/outputs/metrics/exposition.hpp"
#include "daemon/outputs/server/render.hpp"
#include "daemon/outputs/server/render_health.hpp"
#include "tests/server/server_fixture.hpp"

namespace scp::daemon::server {
namespace {

using nlohmann::json;

TEST(Render, VersionErrorAckWatchAreExactLines) {
  EXPECT_EQ(render_version("1.2.3"),
            "{\"class\":\"VERSION\",\"proto_major\":1,\"proto_minor\":17,\"release\":\"1.2.3\"}\n");
  EXPECT_EQ(render_error("bad \"x\""), "{\"class\":\"ERROR\",\"message\":\"bad \\\"x\\\"\"}\n");
  EXPECT_EQ(render_ack("reset", true, "done"),
            "{\"class\":\"ACK\",\"message\":\"done\",\"ok\":true,\"request\":\"reset\"}\n");
  // Empty message omitted (nulls are omitted).
  EXPECT_EQ(render_ack("clear-fault", false, ""),
            "{\"class\":\"ACK\",\"ok\":false,\"request\":\"clear-fault\"}\n");
  EXPECT_EQ(render_watch(false, 0), "{\"class\":\"WATCH\",\"enable\":false}\n");
}

TEST(Render, InvalidUtf8IsReplacedNotThrown) {
  const std::string line = render_error("bad byte \xff here");
  const json parsed = json::parse(line);  // must be valid JSON/UTF-8
  EXPECT_EQ(parsed["class"], "ERROR");
}

// A fault whose 0 V did not reach the device: STATUS must not claim 0 V.
TEST(Render, StatusTellsAnUnconfirmedOutput) {
  PublishedState s = test::sample_state();
  s.state = RunState::fault;
  s.voltage_command = 0.0;
  s.driver.output_v = 1.56;
  s.driver.output_confirmed = false;
  s.driver.late_replies = 7;
  const json j = json::parse(render_status(s, {"0.1.0", "modbus", "", ""}));
  EXPECT_DOUBLE_EQ(j["voltage"].get<double>(), 1.56);
  EXPECT_DOUBLE_EQ(j["voltage_command"].get<double>(), 0.0);
  EXPECT_EQ(j["output"], "unconfirmed");
  EXPECT_EQ(j["driver_stats"]["late_replies"], 7);
}

TEST(Render, Status) {
  PublishedState s = test::sample_state();
  s.state = RunState::fault;
  test::copy_text(s.fault_reason, "x sensor stale for 50 ms");
  const ServerInfo info{"0.1.0", "sim", "/etc/scp.yaml", ""};
  const std::string text = render_status(s, info);
  ASSERT_EQ(text.back(), '\n');
  const json j = json::parse(text);
  EXPECT_EQ(j["class"], "STATUS");
  EXPECT_EQ(j["release"], "0.1.0");
  EXPECT_EQ(j["driver"], "sim");
  EXPECT_EQ(j["config_file"], "/etc/scp.yaml");
  EXPECT_EQ(j["state"], "fault");
  EXPECT_EQ(j["fault_reason"], "x sensor stale for 50 ms");
  EXPECT_DOUBLE_EQ(j["uptime_s"].get<double>(), 12.5);
  EXPECT_DOUBLE_EQ(j["period_s"].get<double>(), 0.001);
  EXPECT_EQ(j["excitation"], true);
  EXPECT_DOUBLE_EQ(j["voltage_command"].get<double>(), 1.75);
  // "voltage" is what the device acknowledged, whatever the loop asked.
  EXPECT_DOUBLE_EQ(j["voltage"].get<double>(), s.driver.output_v);
  EXPECT_EQ(j["output"], s.driver.output_confirmed ? "confirmed" : "unconfirmed");
  EXPECT_DOUBLE_EQ(j["sample"]["x"].get<double>(), 1.25e-3);
  EXPECT_FALSE(j["sample"].contains("xdot"));  // not measured → omitted
  EXPECT_EQ(j["loop"]["cycles"], 12500);
  EXPECT_EQ(j["loop"]["overruns"], 3);
  EXPECT_EQ(j["loop"]["missed_periods"], 4);
  EXPECT_DOUBLE_EQ(j["loop"]["lateness_us"]["min"].get<double>(), 1.5);
  EXPECT_DOUBLE_EQ(j["loop"]["lateness_us"]["mean"].get<double>(), 7.25);
  EXPECT_DOUBLE_EQ(j["loop"]["lateness_us"]["p99"].get<double>(), 32.0);
  EXPECT_DOUBLE_EQ(j["loop"]["lateness_us"]["max"].get<double>(), 80.5);
  EXPECT_DOUBLE_EQ(j["loop"]["exec_us"]["mean"].get<double>(), 3.5);
  EXPECT_DOUBLE_EQ(j["loop"]["exec_us"]["max"].get<double>(), 20.25);
  const json& edges = j["loop"]["histogram"]["edges_us"];
  const json& counts = j["loop"]["histogram"]["counts"];
  ASSERT_EQ(edges.size(), 32U);
  ASSERT_EQ(counts.size(), 32U);
  // Edges 0, 1, 2, 4, ... µs as documented in published_state.hpp.
  EXPECT_EQ(edges[0].get<double>(), 0.0);
  EXPECT_EQ(edges[1].get<double>(), 1.0);
  EXPECT_EQ(edges[2].get<double>(), 2.0);
  EXPECT_EQ(edges[5].get<double>(), 16.0);
  EXPECT_EQ(edges[31].get<double>(), 1073741824.0);
  EXPECT_EQ(counts[0], 100);
  EXPECT_EQ(counts[31], 131);
  EXPECT_EQ(j["driver_stats"]["reads"], 12500);
  EXPECT_EQ(j["driver_stats"]["read_errors"], 1);
  EXPECT_EQ(j["driver_stats"]["writes"], 12499);
  EXPECT_EQ(j["driver_stats"]["write_errors"], 2);
  EXPECT_EQ(j["driver_stats"]["dropped"], 5);
  EXPECT_EQ(j["driver_stats"]["reconnects"], 6);
  EXPECT_EQ(j["driver_stats"]["link_up"], true);

  s.state = RunState::running;
  s.fault_reason.fill('\0');
  const json k = json::parse(render_status(s, ServerInfo{"0.1.0", "sim", "", ""}));
  EXPECT_FALSE(k.contains("fault_reason"));
  EXPECT_FALSE(k.contains("config_file"));
}

TEST(Render, EstimateWithTruthAndPhysical) {
  const PublishedState s = test::sample_state();
  const json j = json::parse(render_estimate(s.estimate));
  EXPECT_EQ(j["class"], "ESTIMATE");
  EXPECT_DOUBLE_EQ(j["t"].get<double>(), 12.5);
  ASSERT_EQ(j["theta_hat"].size(), 6U);
  EXPECT_DOUBLE_EQ(j["theta_hat"][0].get<double>(), 1247.0 * 1.01);
  EXPECT_TRUE(j["sigma"][2].is_null());  // infinite → null, index kept
  EXPECT_DOUBLE_EQ(j["sigma"][3].get<double>(), 2.0);
  EXPECT_DOUBLE_EQ(j["eps"][1].get<double>(), -2e-7);
  EXPECT_DOUBLE_EQ(j["af"][1].get<double>(), 0.3);
  EXPECT_DOUBLE_EQ(j["af_hat"][0].get<double>(), 0.011);
  EXPECT_DOUBLE_EQ(j["excitation"]["mechanical"].get<double>(), 0.25);
  EXPECT_DOUBLE_EQ(j["excitation"]["thermal"].get<double>(), 0.75);
  EXPECT_DOUBLE_EQ(j["p_max_eig"]["mechanical"].get<double>(), 4.0e6);
  EXPECT_DOUBLE_EQ(j["p_max_eig"]["thermal"].get<double>(), 12.5);
  EXPECT_EQ(j["converged"]["mechanical"], false);
  EXPECT_EQ(j["converged"]["thermal"], true);
  EXPECT_EQ(j["updates"], 12500);
  EXPECT_EQ(j["skipped"], 7);
  EXPECT_DOUBLE_EQ(j["theta_true"][4].get<double>(), 0.0594059);
  // θ̂ᵢ = θᵢ(1 + 0.01(i+1)) by construction, so rel_error must be 0.01(i+1).
  for (std::size_t i = 0; i < 6; ++i)
    EXPECT_NEAR(j["rel_error"][i].get<double>(), 0.01 * static_cast<double>(i + 1), 1e-12) << i;
  EXPECT_DOUBLE_EQ(j["physical"]["b"].get<double>(), 124.7);
  EXPECT_DOUBLE_EQ(j["physical"]["k"].get<double>(), 181.3);
  EXPECT_DOUBLE_EQ(j["physical"]["alpha1"].get<double>(), 0.08);
  EXPECT_DOUBLE_EQ(j["physical"]["alpha2"].get<double>(), 0.01);
  EXPECT_DOUBLE_EQ(j["physical"]["lambda"].get<double>(), 0.054);
  EXPECT_DOUBLE_EQ(j["physical"]["Cth"].get<double>(), 0.909);
}

TEST(Render, EstimateWithoutTruthOmitsThem) {
  EstimateView e = test::sample_state().estimate;
  e.has_truth = false;
  e.has_physical = false;
  e.t = std::nan("");
  const json j = json::parse(render_estimate(e));
  EXPECT_FALSE(j.contains("theta_true"));
  EXPECT_FALSE(j.contains("rel_error"));
  EXPECT_FALSE(j.contains("physical"));
  EXPECT_FALSE(j.contains("t"));
}

refine::RefinedView sample_refined() {
  refine::RefinedView r;
  r.valid = true;
  r.fits = 4;
  r.converged_fits = 3;
  r.windows = 2;
  r.interval_s = 10.0;
  r.fitted_at_t = 12.0;
  r.fitted_at_unix_ns = 1'795'422'600'123'456'789;  // 2026-11-23T08:30:00.123Z
  r.duration_s = 0.5;
  r.seed = refine::Seed::refined;
  r.theta_hat = {1247.0, 0.8, 1813.0, 0.1, 0.0594059 * 1.5, 1.1001100};
  r.sigma = {1.0, 0.001, 2.0, 1e-4, 1e-7, 2e-7};
  r.t_begin = 2.0;
  r.t_end = 12.0;
  r.samples = 10001;
  r.residual_rms = {1e-7, 1e-3};
  r.noise_sigma = {0.9e-7, std::nan("")};
  r.converged = true;
  r.iterations = 6;
  std::snprintf(r.message.data(), r.message.size(), "%s", "converged");
  r.bias_tested = true;
  r.paper_biased = {true, false};
  r.bias_statistic = {400.0, 1.0};
  r.bias_threshold = {18.47, 13.82};
  // Issue 28: both estimates validated and passed.
  r.validated = true;
  r.validation.mechanical.verdict = scp::refine::Verdict::kAdequate;
  r.validation.thermal.verdict = scp::refine::Verdict::kAdequate;
  r.paper_validated = true;
  r.paper_validation.mechanical.verdict = scp::refine::Verdict::kAdequate;
  r.paper_validation.thermal.verdict = scp::refine::Verdict::kNoiseColored;
  return r;
}

TEST(Render, EstimateWithoutAFitRecommendsThePaperLawUnflagged) {
  const PublishedState s = test::sample_state();
  for (const json& j : {json::parse(render_estimate(s.estimate)),
                        json::parse(render_estimate(s.estimate, nullptr, 12.5))}) {
    EXPECT_EQ(j["best"], "paper");
    EXPECT_EQ(j["paper_biased"]["mechanical"], false);
    EXPECT_EQ(j["paper_biased"]["thermal"], false);
    EXPECT_FALSE(j.contains("refined"));
  }
  const refine::RefinedView none;  // enabled, no fit finished yet
  const json j = json::parse(render_estimate(s.estimate, &none, 12.5));
  EXPECT_EQ(j["best"], "paper");
  EXPECT_FALSE(j.contains("refined"));
}

TEST(Render, EstimateCarriesTheRefinedFit) {
  const PublishedState s = test::sample_state();
  const refine::RefinedView r = sample_refined();
  const json j = json::parse(render_estimate(s.estimate, &r, 12.5));
  EXPECT_EQ(j["best"], "refined");
  EXPECT_EQ(j["paper_biased"]["mechanical"], true);
  EXPECT_EQ(j["paper_biased"]["thermal"], false);
  // The paper law's members are unchanged.
  EXPECT_DOUBLE_EQ(j["theta_hat"][0].get<double>(), 1247.0 * 1.01);
  const json& o = j["refined"];
  ASSERT_EQ(o["theta_hat"].size(), 6U);
  EXPECT_DOUBLE_EQ(o["theta_hat"][2].get<double>(), 1813.0);
  EXPECT_DOUBLE_EQ(o["sigma"][5].get<double>(), 2e-7);
  EXPECT_DOUBLE_EQ(o["window"]["t_begin"].get<double>(), 2.0);
  EXPECT_DOUBLE_EQ(o["window"]["t_end"].get<double>(), 12.0);
  EXPECT_EQ(o["window"]["samples"], 10001);
  EXPECT_DOUBLE_EQ(o["fitted_at"]["t"].get<double>(), 12.0);
  EXPECT_EQ(o["fitted_at"]["utc"], "2026-11-23T08:30:00.123Z");
  EXPECT_EQ(o["fitted_at"]["unix_ns"], 1'795'422'600'123'456'789);
  EXPECT_DOUBLE_EQ(o["residual_rms"]["x"].get<double>(), 1e-7);
  EXPECT_DOUBLE_EQ(o["residual_rms"]["T"].get<double>(), 1e-3);
  EXPECT_DOUBLE_EQ(o["noise_sigma"]["x"].get<double>(), 0.9e-7);
  EXPECT_FALSE(o["noise_sigma"].contains("T")) << "non-finite: omitted";
  EXPECT_EQ(o["converged"], true);
  EXPECT_EQ(o["iterations"], 6);
  EXPECT_EQ(o["message"], "converged");
  EXPECT_EQ(o["seed"], "refined");
  EXPECT_EQ(o["fits"], 4);
  EXPECT_EQ(o["converged_fits"], 3);
  EXPECT_EQ(o["windows"], 2);
  EXPECT_DOUBLE_EQ(o["bias_test"]["mechanical"]["statistic"].get<double>(), 400.0);
  EXPECT_DOUBLE_EQ(o["bias_test"]["thermal"]["threshold"].get<double>(), 13.82);
  // The simulated driver's truth applies to the refined θ̂ too.
  EXPECT_NEAR(o["rel_error"][0].get<double>(), 0.0, 1e-12);
  EXPECT_NEAR(o["rel_error"][4].get<double>(), 0.5, 1e-12);
  EXPECT_DOUBLE_EQ(o["theta_true"][4].get<double>(), 0.0594059);
}

// Issue 29: whether the latest fit was a warm refit, and why not when one was offered.
TEST(Render, EstimateSaysWhetherTheFitWasWarm) {
  const PublishedState s = test::sample_state();
  refine::RefinedView r = sample_refined();
  r.warm = true;
  r.warm_fallback = scp::refine::WarmFallback::none;
  r.warm_fits = 2;
  r.evaluations = 5;
  json o = json::parse(render_estimate(s.estimate, &r, 12.5))["refined"];
  EXPECT_EQ(o["warm"], true);
  EXPECT_EQ(o["warm_fits"], 2);
  EXPECT_EQ(o["evaluations"], 5);
  EXPECT_FALSE(o.contains("warm_fallback"));
  r.warm = false;
  r.warm_fallback = scp::refine::WarmFallback::not_converged;
  o = json::parse(render_estimate(s.estimate, &r, 12.5))["refined"];
  EXPECT_EQ(o["warm"], false);
  EXPECT_EQ(o["warm_fallback"], "not_converged");
  r.warm_fallback = scp::refine::WarmFallback::not_requested;  // a window's first fit
  o = json::parse(render_estimate(s.estimate, &r, 12.5))["refined"];
  EXPECT_FALSE(o.contains("warm_fallback"));
}

TEST(Render, BestFallsBackToThePaperLawWhenTheFitIsStaleOrFailed) {
  const PublishedState s = test::sample_state();
  refine::RefinedView r = sample_refined();
  EXPECT_EQ(json::parse(render_estimate(s.estimate, &r, 42.0))["best"], "refined");
  EXPECT_EQ(json::parse(render_estimate(s.estimate, &r, 42.5))["best"], "paper");
  r.converged = false;
  const json j = json::parse(render_estimate(s.estimate, &r, 12.5));
  EXPECT_EQ(j["best"], "paper");
  EXPECT_EQ(j["refined"]["converged"], false);
  EXPECT_EQ(j["paper_biased"]["mechanical"], true) << "held from the last converged fit";
}

// Issue 28: a refined fit whose validation found structure is never `best`; the paper law is when
// its own prediction passed, else none, and the reason names the failing test and the remedy. The
// validation is published per block with its failing tests.
TEST(Render, BestNamesOnlyAnEstimateWhoseValidationPassed) {
  const PublishedState s = test::sample_state();
  refine::RefinedView r = sample_refined();
  r.validation.thermal.verdict = scp::refine::Verdict::kStructure;
  r.validation.thermal.decisive = scp::refine::ValidationTest::kResistanceTempco;
  r.validation.thermal.fit_percent = 97.5;
  auto& t = r.validation.tests[static_cast<int>(scp::refine::ValidationTest::kResistanceTempco)];
  t.performed = true;
  t.failed = true;
  t.p_value = 1e-9;
  t.effect = 0.0041;
  json j = json::parse(render_estimate(s.estimate, &r, 12.5));
  EXPECT_EQ(j["best"], "paper");
  const json& thermal = j["refined"]["validation"]["thermal"];
  EXPECT_EQ(thermal["verdict"], "structure");
  EXPECT_EQ(thermal["decisive"], "resistance_tempco");
  EXPECT_DOUBLE_EQ(thermal["fit_percent"].get<double>(), 97.5);
  ASSERT_EQ(thermal["failed"].size(), 1U);
  EXPECT_EQ(thermal["failed"][0]["test"], "resistance_tempco");
  EXPECT_DOUBLE_EQ(thermal["failed"][0]["effect"].get<double>(), 0.0041);
  EXPECT_EQ(j["refined"]["validation"]["mechanical"]["failed"].size(), 0U);
  EXPECT_EQ(j["paper_validation"]["thermal"]["verdict"], "noise_colored");
  const std::string reason = j["best_reason"].get<std::string>();
  EXPECT_NE(reason.find("resistance_tempco (0.0041)"), std::string::npos) << reason;
  EXPECT_NE(reason.find("refine.extensions.resistance_tempco"), std::string::npos) << reason;

  r.paper_validation.mechanical.verdict = scp::refine::Verdict::kStructure;
  r.paper_validation.mechanical.decisive = scp::refine::ValidationTest::kIndependenceX;
  j = json::parse(render_estimate(s.estimate, &r, 12.5));
  EXPECT_EQ(j["best"], "none");
  EXPECT_NE(j["best_reason"].get<std::string>().find("paper law mechanical structure"),
            std::string::npos)
      << j["best_reason"];

  r.validated = false;  // a converged fit nobody validated is not recommended either
  r.paper_validation.mechanical.verdict = scp::refine::Verdict::kAdequate;
  EXPECT_EQ(json::parse(render_estimate(s.estimate, &r, 12.5))["best"], "paper");
}

// Issue 28: a voltage interval the fit estimated but the window could not tell is published as
// `undetermined` (with the criterion's evidence), and `best` keeps off the refined estimate (its
// θ1..θ4 are a guess's) with the remedy in the reason, unless the fit under the other interval
// left θ1..θ4 where they were (equivalent); one the data decided changes nothing.
TEST(Render, AnUndeterminedVoltageIntervalIsSaidAndNotRecommended) {
  const PublishedState s = test::sample_state();
  refine::RefinedView r = sample_refined();
  r.voltage_interval = scp::refine::VoltageInterval::after;
  r.voltage_interval_evidence = {
      .estimated = true, .determined = true, .statistic = 40.0, .threshold = 6.6};
  json j = json::parse(render_estimate(s.estimate, &r, 12.5));
  EXPECT_EQ(j["best"], "refined");
  EXPECT_EQ(j["refined"]["voltage_interval"], "after");
  EXPECT_EQ(j["refined"]["voltage_interval_test"]["fitted"], "after");
  EXPECT_EQ(j["refined"]["voltage_interval_test"]["determined"], true);

  r.voltage_interval_evidence = {
      .estimated = true, .determined = false, .statistic = 0.5, .threshold = 6.6};
  j = json::parse(render_estimate(s.estimate, &r, 12.5));
  EXPECT_EQ(j["best"], "paper");
  EXPECT_EQ(j["refined"]["voltage_interval"], "undetermined");
  EXPECT_EQ(j["refined"]["voltage_interval_test"]["fitted"], "after");
  EXPECT_DOUBLE_EQ(j["refined"]["voltage_interval_test"]["statistic"].get<double>(), 0.5);
  const std::string reason = j["best_reason"].get<std::string>();
  EXPECT_NE(reason.find("refine.voltage_interval"), std::string::npos) << reason;
  EXPECT_NE(reason.find("V_since"), std::string::npos) << reason;
  const json status = json::parse(render_status(s, ServerInfo{"0.1.0", "sim", "", ""}, &r));
  EXPECT_EQ(status["refine"]["voltage_interval"], "undetermined");

  // Fitted both ways, θ1..θ4 moved by more than a quarter σ: still undetermined, the shift said.
  r.voltage_interval_evidence.compared = true;
  r.voltage_interval_evidence.theta_shift_sigma = 3.0;
  j = json::parse(render_estimate(s.estimate, &r, 12.5));
  EXPECT_EQ(j["refined"]["voltage_interval"], "undetermined");
  EXPECT_EQ(j["refined"]["voltage_interval_test"]["equivalent"], false);
  EXPECT_DOUBLE_EQ(j["refined"]["voltage_interval_test"]["theta_shift_sigma"].get<double>(), 3.0);
  EXPECT_EQ(j["best"], "paper");
  // Equivalent: the fitted interval is named, the test says it was not determined, and the
  // refined estimate may be best.
  r.voltage_interval_evidence.equivalent = true;
  r.voltage_interval_evidence.theta_shift_sigma = 0.1;
  j = json::parse(render_estimate(s.estimate, &r, 12.5));
  EXPECT_EQ(j["refined"]["voltage_interval"], "after");
  EXPECT_EQ(j["refined"]["voltage_interval_test"]["determined"], false);
  EXPECT_EQ(j["refined"]["voltage_interval_test"]["equivalent"], true);
  EXPECT_EQ(j["best"], "refined");
  r.voltage_interval_evidence.equivalent = false;

  r.paper_validation.mechanical.verdict = scp::refine::Verdict::kStructure;
  EXPECT_EQ(json::parse(render_estimate(s.estimate, &r, 12.5))["best"], "none");
  r.voltage_interval_evidence = {};  // declared: nothing to doubt
  j = json::parse(render_estimate(s.estimate, &r, 12.5));
  EXPECT_EQ(j["best"], "refined");
  EXPECT_FALSE(j["refined"].contains("voltage_interval_test"));
}

// An interval the thermal stage left undetermined and the joint fits under both decided: the test
// says the statistic is theirs and gives the thermal stage's beside it; the interval is named and
// the refined estimate may be best. Without the joint weighing neither member appears.
TEST(Render, AnIntervalTheJointFitsDecidedSaysSo) {
  const PublishedState s = test::sample_state();
  refine::RefinedView r = sample_refined();
  r.voltage_interval = scp::refine::VoltageInterval::before;
  r.voltage_interval_evidence = {.estimated = true,
                                 .determined = true,
                                 .statistic = 108.5,
                                 .threshold = 6.6,
                                 .compared = true,
                                 .equivalent = true,
                                 .theta_shift_sigma = 0.15,
                                 .joint = true,
                                 .thermal_statistic = 1.4};
  json j = json::parse(render_estimate(s.estimate, &r, 12.5));
  const json& test = j["refined"]["voltage_interval_test"];
  EXPECT_EQ(test["joint"], true);
  EXPECT_DOUBLE_EQ(test["statistic"].get<double>(), 108.5);
  EXPECT_DOUBLE_EQ(test["thermal_statistic"].get<double>(), 1.4);
  EXPECT_EQ(test["determined"], true);
  EXPECT_EQ(test["joint_lag_held"], false);
  EXPECT_EQ(j["refined"]["voltage_interval"], "before");
  EXPECT_EQ(j["best"], "refined");

  // Weighed with the sensor's lag held: said, and standing where it decides nothing.
  r.voltage_interval_evidence.joint_lag_held = true;
  r.voltage_interval_evidence.determined = false;
  r.voltage_interval_evidence.statistic = 4.2;
  r.voltage_interval_evidence.equivalent = false;
  j = json::parse(render_estimate(s.estimate, &r, 12.5));
  EXPECT_EQ(j["refined"]["voltage_interval_test"]["joint_lag_held"], true);
  EXPECT_EQ(j["refined"]["voltage_interval_test"]["determined"], false);
  EXPECT_EQ(j["refined"]["voltage_interval"], "undetermined");
  EXPECT_NE(j["best"], "refined");
  r.voltage_interval_evidence.determined = true;
  r.voltage_interval_evidence.statistic = 108.5;
  r.voltage_interval_evidence.equivalent = true;

  r.voltage_interval_evidence.joint = false;
  j = json::parse(render_estimate(s.estimate, &r, 12.5));
  EXPECT_FALSE(j["refined"]["voltage_interval_test"].contains("joint"));
  EXPECT_FALSE(j["refined"]["voltage_interval_test"].contains("thermal_statistic"));
}

// A declared interval the data were weighed against: the test says so, and where the data
// determined the other interval `best` keeps off the refined estimate, naming the declaration and
// the remedy; STATUS says `contradicted`.
TEST(Render, AContradictedDeclaredIntervalIsSaidAndNotRecommended) {
  const PublishedState s = test::sample_state();
  refine::RefinedView r = sample_refined();
  r.voltage_interval = scp::refine::VoltageInterval::before;
  r.voltage_interval_evidence = {
      .determined = true, .statistic = 40.0, .threshold = 6.6, .checked = true};
  json j = json::parse(render_estimate(s.estimate, &r, 12.5));
  EXPECT_EQ(j["best"], "refined");
  EXPECT_EQ(j["refined"]["voltage_interval"], "before");
  EXPECT_EQ(j["refined"]["voltage_interval_test"]["declared"], true);
  EXPECT_EQ(j["refined"]["voltage_interval_test"]["contradicted"], false);

  r.voltage_interval_evidence.contradicted = true;
  j = json::parse(render_estimate(s.estimate, &r, 12.5));
  EXPECT_EQ(j["best"], "paper");
  EXPECT_EQ(j["refined"]["voltage_interval"], "before");
  EXPECT_EQ(j["refined"]["voltage_interval_test"]["contradicted"], true);
  const std::string reason = j["best_reason"].get<std::string>();
  EXPECT_NE(reason.find("contradict the declared refine.voltage_interval 'before'"),
            std::string::npos)
      << reason;
  EXPECT_NE(reason.find("estimate"), std::string::npos) << reason;
  const json status = json::parse(render_status(s, ServerInfo{"0.1.0", "sim", "", ""}, &r));
  EXPECT_EQ(status["refine"]["voltage_interval"], "contradicted");
}

// The metrics carry each estimate's verdict per block as a state set, its fit %, and which
// estimate is best (none included): what ESTIMATE says, so a dashboard cannot show a failed σ as
// trustworthy.
TEST(Render, MetricsCarryTheVerdictPerBlockAndBest) {
  const PublishedState s = test::sample_state();
  refine::RefinedView r = sample_refined();
  r.validation.mechanical.fit_percent = 99.5;
  r.validation.thermal.verdict = scp::refine::Verdict::kStructure;
  r.paper_validation.thermal.verdict = scp::refine::Verdict::kUntested;
  const json estimate = json::parse(render_estimate(s.estimate, &r, 12.5));
  const std::string text = metrics::exposition(json::object(), estimate, "bench-a");
  const auto has = [&](const std::string& part) { return text.find(part) != std::string::npos; };
  EXPECT_TRUE(
      has("scp_estimator_validation_verdict{actuator=\"bench-a\",estimator=\"refined\","
          "block=\"thermal\",verdict=\"structure\"} 1"))
      << text;
  EXPECT_TRUE(
      has("scp_estimator_validation_verdict{actuator=\"bench-a\",estimator=\"refined\","
          "block=\"thermal\",verdict=\"adequate\"} 0"))
      << text;
  EXPECT_TRUE(
      has("scp_estimator_validation_fit_percent{actuator=\"bench-a\",estimator="
          "\"refined\",block=\"mechanical\"} 99.5"))
      << text;
  EXPECT_TRUE(has("scp_estimator_best{actuator=\"bench-a\",estimate=\"none\"} 1")) << text;
  EXPECT_TRUE(has("scp_estimator_best_refined{actuator=\"bench-a\"} 0")) << text;
}

TEST(Render, StatusCarriesTheRefinementCounters) {
  PublishedState s = test::sample_state();
  s.handoff_dropped = 3;
  const refine::RefinedView r = sample_refined();
  const json j = json::parse(render_status(s, ServerInfo{"0.1.0", "sim", "", ""}, &r));
  EXPECT_EQ(j["refine"]["fits"], 4);
  EXPECT_EQ(j["refine"]["converged_fits"], 3);
  EXPECT_EQ(j["refine"]["windows"], 2);
  EXPECT_EQ(j["refine"]["warm_fits"], 0);
  EXPECT_EQ(j["refine"]["handoff_dropped"], 3);
  EXPECT_DOUBLE_EQ(j["refine"]["last_fit_duration_s"].get<double>(), 0.5);
  EXPECT_FALSE(json::parse(render_status(s, ServerInfo{"0.1.0", "sim", "", ""})).contains("refine"))
      << "refinement disabled";
}

// With the loop's fine histogram, STATUS takes p50/p99/p99_9 from it (µs, within 0.4 %) and lists
// its non-empty buckets so that a client can take the difference of two STATUS replies.
TEST(Render, StatusLatenessFromTheFineHistogram) {
  auto hist = std::make_unique<rt::LatencyHistogram>();
  for (int i = 1; i <= 1000; ++i) hist->record(i * 1000);  // 1 µs .. 1000 µs
  auto snap = std::make_unique<rt::LatencyHistogram::Snapshot>();
  hist->snapshot(*snap);
  PublishedState s = test::sample_state();
  const json j =
      json::parse(render_status(s, ServerInfo{"0.1.0", "sim", "", ""}, nullptr, snap.get()));
  const json& lateness = j["loop"]["lateness_us"];
  EXPECT_NEAR(lateness["p50"].get<double>(), 500.0, 500.0 / 256);
  EXPECT_NEAR(lateness["p99"].get<double>(), 990.0, 990.0 / 256);
  EXPECT_NEAR(lateness["p99_9"].get<double>(), 999.0, 999.0 / 256);
  const json& fine = j["loop"]["lateness_histogram_ns"];
  EXPECT_EQ(fine["count"], 1000);
  EXPECT_EQ(fine["max"], 1000000);
  std::uint64_t total = 0;
  for (const json& b : fine["buckets"]) {
    const auto lower = b[0].get<std::uint64_t>(), upper = b[1].get<std::uint64_t>();
    EXPECT_LT(lower, upper);
    EXPECT_LE(static_cast<double>(upper - lower), std::max(1.0, lower / 128.0));
    total += b[2].get<std::uint64_t>();
  }
  EXPECT_EQ(total, 1000U);
  // Without it: the coarse histogram's percentiles, no p99_9, no bucket list.
  const json coarse = json::parse(render_status(s, ServerInfo{"0.1.0", "sim", "", ""}));
  EXPECT_FALSE(coarse["loop"]["lateness_us"].contains("p99_9"));
  EXPECT_FALSE(coarse["loop"].contains("lateness_histogram_ns"));
}

// The health object follows the protocol's rule: a member with no value is omitted, never null
// (a change point that names no parameter, a shift or indicator whose value is not finite).
TEST(Render, HealthOmitsMembersWithNoValue) {
  const double nan = std::nan("");
  health::HealthView v;
  v.baseline_present = true;
  scp::health::HealthReport& r = v.report;
  r.has_change = true;
  r.change.parameter = -1;
  r.change.onset = nan;
  r.change.detected_at = 5.0;
  r.change.parameters[0] = {.tested = true, .delta = nan, .sigma = 1.0, .z = nan, .relative = nan};
  r.has_window = true;
  r.baseline_deviation.blocks[0].statistic = nan;
  r.baseline_deviation.parameters[1] = r.change.parameters[0];
  r.fast.ratio.fill(nan);
  r.fast.ratio[5] = 0.5;
  r.indicators[0] = {.known = true, .value = nan, .sigma = 2.0};
  const json h = health_json(v, /*full=*/true);
  EXPECT_EQ(h.dump().find("null"), std::string::npos) << h.dump();
  EXPECT_FALSE(h["change"].contains("parameter")) << h["change"].dump();
  EXPECT_FALSE(h["change"].contains("onset")) << h["change"].dump();
  EXPECT_EQ(h["change"]["detected_at"], 5.0);
  ASSERT_EQ(h["change"]["parameters"].size(), 1U);
  EXPECT_EQ(h["change"]["parameters"][0]["sigma"], 1.0);
  EXPECT_FALSE(h["change"]["parameters"][0].contains("delta"));
  EXPECT_EQ(h["fast"]["cusum_ratio"].size(), 1U) << h["fast"].dump();
  EXPECT_FALSE(h["baseline_deviation"]["blocks"]["mechanical"].contains("chi2"));
}

TEST(Render, StateNames) {
  EXPECT_STREQ(to_string(RunState::starting), "starting");
  EXPECT_STREQ(to_string(RunState::running), "running");
  EXPECT_STREQ(to_string(RunState::fault), "fault");
  EXPECT_STREQ(to_string(RunState::stopping), "stopping");
}

}  // namespace
}  // namespace scp::daemon::server

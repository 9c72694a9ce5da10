#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>

#include "daemon/server/render.hpp"
#include "tests/server/server_fixture.hpp"

namespace scp::daemon::server {
namespace {

using nlohmann::json;

TEST(Render, VersionErrorAckWatchAreExactLines) {
  EXPECT_EQ(render_version("1.2.3"),
            "{\"class\":\"VERSION\",\"proto_major\":1,\"proto_minor\":0,\"release\":\"1.2.3\"}\n");
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

TEST(Render, Status) {
  PublishedState s = test::sample_state();
  s.state = RunState::fault;
  test::copy_text(s.fault_reason, "x sensor stale for 50 ms");
  const ServerInfo info{"0.1.0", "sim", "/etc/scp.yaml"};
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
  EXPECT_DOUBLE_EQ(j["voltage"].get<double>(), 1.75);
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
  const json k = json::parse(render_status(s, ServerInfo{"0.1.0", "sim", ""}));
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

TEST(Render, StateNames) {
  EXPECT_STREQ(state_name(RunState::starting), "starting");
  EXPECT_STREQ(state_name(RunState::running), "running");
  EXPECT_STREQ(state_name(RunState::fault), "fault");
  EXPECT_STREQ(state_name(RunState::stopping), "stopping");
}

}  // namespace
}  // namespace scp::daemon::server

// Issue 8: the output-error refinement beside the paper's law, through the real daemon: offline
// (the batch summary of scp-estimatord --offline, --replay of its own recording) and in real time
// (the ESTIMATE object over the socket, scp-estimatorctl get).

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <sstream>

#include "tests/e2e/e2e_util.hpp"

namespace scp::test {
namespace {

// Good lab sensors (the N1): the paper's law is biased toward zero by a common factor on
// θ1..θ4 while its σ claims otherwise; the refined fit must land within a few of its own σ of the
// truth, be recommended, and flag the paper law's mechanical block. If the hand-off, the window,
// the seed or the bias test were broken, refined would be missing, far off or unflagged.
TEST(Refined, NoisyBatchRunRecommendsTheRefinedEstimateAndFlagsThePaperLaw) {
  TempDir dir;
  json cfg = merge_config(
      base_config(dir.path()),
      {{"driver",
        {{"sim", {{"noise", {{"x", 1e-7}, {"xdot", 1e-6}, {"temperature", 1e-3}, {"seed", 7}}}}}}},
       {"refine", {{"window_s", 300}, {"interval_s", 50}, {"min_window_s", 30}}}});
  write_config(dir.file("noisy.yaml"), cfg);
  const ProcessResult r = run_process(
      {estimatord_path(), "--config", dir.file("noisy.yaml"), "--offline", "--duration", "300"},
      Seconds(900));
  ASSERT_EQ(r.exit_code, 0) << r.err << r.out;
  std::printf("%s", r.out.c_str());
  const json s = summary_of(r);
  ASSERT_TRUE(s.contains("refined")) << s.dump();
  const json& ref = s["refined"];
  EXPECT_EQ(ref["converged"], true) << ref.dump();
  EXPECT_NEAR(ref["window"]["t_end"].get<double>(), 300.0, 0.01);
  EXPECT_NEAR(ref["window"]["t_end"].get<double>() - ref["window"]["t_begin"].get<double>(), 300.0,
              0.01);
  for (std::size_t i = 0; i < 6; ++i) {
    const double hat = ref["theta_hat"][i].get<double>();
    const double sigma = ref["sigma"][i].get<double>();
    const double truth = theta_true()[i];
    EXPECT_GT(sigma, 0.0) << "theta" << i + 1;
    EXPECT_LE(std::fabs(hat - truth), 4.0 * sigma)
        << "theta" << i + 1 << ": refined " << hat << " sigma " << sigma << " true " << truth;
    // And σ itself is small enough to matter: the issue measured 0.77 % on θ1..θ4 at N1.
    EXPECT_LT(sigma / std::fabs(truth), i < 4 ? 0.03 : 1e-4) << "theta" << i + 1;
  }
  EXPECT_EQ(s["best"], "refined");
  EXPECT_EQ(s["paper_biased"]["mechanical"], true) << s["refined"]["bias_test"].dump();
  // One fit per interval (at 30, 80, ..., 280 s) and one at the end.
  EXPECT_EQ(s["refine"]["fits"].get<int>(), 7) << s["refine"].dump();
  EXPECT_EQ(s["refine"]["handoff_dropped"].get<int>(), 0);
  // The table shows both estimates.
  EXPECT_TRUE(contains(r.out, "refined")) << r.out;
  EXPECT_TRUE(contains(r.out, "best: refined")) << r.out;
}

// A replay runs to the end of its file unless --duration says otherwise (it used to stop at 200 s),
// and its summary carries the refined fit of the final window. The recording carries the refined
// columns and still replays as it is.
TEST(Refined, ReplayRunsToTheEndOfItsFileAndRefines) {
  TempDir dir;
  json cfg =
      merge_config(base_config(dir.path()),
                   {{"refine", {{"window_s", 60}, {"interval_s", 100}, {"min_window_s", 30}}}});
  write_config(dir.file("c.yaml"), cfg);
  const std::string csv = dir.file("run.csv");
  const ProcessResult rec = run_process({estimatord_path(), "--config", dir.file("c.yaml"),
                                         "--offline", "--duration", "230", "--record", csv},
                                        Seconds(600));
  ASSERT_EQ(rec.exit_code, 0) << rec.err;
  std::string header;
  {
    std::istringstream text(read_text(csv));
    std::getline(text, header);
  }
  for (const char* column :
       {"refined_theta_hat1", "refined_sigma6", "best", "paper_biased_mechanical",
        "paper_biased_thermal", "refined_converged"}) {
    EXPECT_TRUE(contains(header, column)) << column << " missing from " << header;
  }

  const ProcessResult all =
      run_process({estimatord_path(), "--config", dir.file("c.yaml"), "--offline", "--replay", csv},
                  Seconds(600));
  ASSERT_EQ(all.exit_code, 0) << all.err;
  const json s = summary_of(all);
  EXPECT_EQ(s["driver"], "replay");
  EXPECT_GT(s["t"].get<double>(), 229.9) << "the replay stopped before the end of its file";
  ASSERT_TRUE(s.contains("refined")) << s.dump();
  EXPECT_GT(s["refined"]["window"]["t_end"].get<double>(), 229.9);
  EXPECT_NEAR(s["refined"]["window"]["t_end"].get<double>() -
                  s["refined"]["window"]["t_begin"].get<double>(),
              60.0, 0.01);

  const ProcessResult part = run_process({estimatord_path(), "--config", dir.file("c.yaml"),
                                          "--offline", "--replay", csv, "--duration", "50"},
                                         Seconds(600));
  ASSERT_EQ(part.exit_code, 0) << part.err;
  EXPECT_NEAR(summary_of(part)["t"].get<double>(), 50.0, 0.01);
}

// In real time the worker thread fits beside the loop and the fit appears over the socket (a short
// window so the test is quick); scp-estimatorctl shows both estimates.
TEST(Refined, RefinedFitAppearsOverTheSocketInRealTime) {
  TempDir dir;
  // A loaded test machine stalls the loop now and then; every stall longer than
  // refine.max_gap_s restarts the window, so the window might never span min_window_s. Up to 1 s
  // is tolerated here.
  DaemonProcess daemon(
      dir,
      {{"refine",
        {{"window_s", 20.0}, {"interval_s", 5.0}, {"min_window_s", 15.0}, {"max_gap_s", 1.0}}}});
  daemon.start();
  json first;
  const auto deadline = std::chrono::steady_clock::now() + Seconds(90);
  while (std::chrono::steady_clock::now() < deadline) {
    first = daemon.estimate();
    if (first.contains("refined")) break;
    sleep_s(0.2);
  }
  ASSERT_TRUE(first.contains("refined")) << first.dump() << daemon.stderr_text();
  // Later fits follow, each on the newest window.
  json later;
  while (std::chrono::steady_clock::now() < deadline) {
    later = daemon.estimate();
    if (later.contains("refined") &&
        later["refined"]["fits"].get<int>() >= first["refined"]["fits"].get<int>() + 1)
      break;
    sleep_s(0.2);
  }
  ASSERT_TRUE(later.contains("refined")) << later.dump();
  const json& r = later["refined"];
  std::printf("refined after %d fits: %s\n", r["fits"].get<int>(), r.dump().c_str());
  EXPECT_GE(r["fits"].get<int>(), first["refined"]["fits"].get<int>() + 1) << r.dump();
  EXPECT_GT(r["window"]["t_end"].get<double>(), first["refined"]["window"]["t_end"].get<double>());
  EXPECT_LE(r["window"]["t_end"].get<double>() - r["window"]["t_begin"].get<double>(), 20.0 + 1e-6);
  EXPECT_GT(r["window"]["samples"].get<int>(), 14900);
  EXPECT_TRUE(r["fitted_at"].contains("utc"));
  EXPECT_EQ(r["converged"], true) << r.dump();
  for (int i = 0; i < 6; ++i) {
    // Noise-free: the refined θ̂ of a 20 s window is close to Table I.
    const double hat = r["theta_hat"][static_cast<std::size_t>(i)].get<double>();
    const double truth = theta_true()[static_cast<std::size_t>(i)];
    EXPECT_LT(std::fabs(hat - truth) / truth, 0.05) << "theta" << i + 1 << " " << r.dump();
  }
  EXPECT_TRUE(later.contains("best"));
  EXPECT_TRUE(later.contains("paper_biased"));

  const json status = daemon.status();
  ASSERT_TRUE(status.contains("refine")) << status.dump();
  std::printf("STATUS refine %s, loop overruns %s\n", status["refine"].dump().c_str(),
              status["loop"]["overruns"].dump().c_str());
  EXPECT_GE(status["refine"]["fits"].get<int>(), 2);
  EXPECT_EQ(status["refine"]["handoff_dropped"].get<int>(), 0);

  const ProcessResult get = daemon.run_ctl({"get"});
  ASSERT_EQ(get.exit_code, 0) << get.err;
  std::printf("%s", get.out.c_str());
  EXPECT_TRUE(contains(get.out, "refined")) << get.out;
  EXPECT_TRUE(contains(get.out, "best: ")) << get.out;
}

// The loop thread allocates nothing after its start-up while the worker fits beside it: the
// daemon linked with the allocation counter (bench/), a fit every second on a growing window.
TEST(Refined, LoopAllocatesNothingWhileTheWorkerFits) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  // A sanitizer owns malloc: the counting daemon cannot be built beside it (bench/alloc_counter).
  GTEST_SKIP() << "allocation counting is not possible under a sanitizer (scripts/sanitize)";
#elif !defined(SCP_ALLOCCOUNT_PATH)
  // Built without SCP_BUILD_BENCH: no counting daemon. CI builds it, so there it is a failure.
  if (std::getenv("CI") != nullptr) FAIL() << "scp-estimatord-alloccount was not built";
  GTEST_SKIP() << "scp-estimatord-alloccount not built (SCP_BUILD_BENCH=OFF)";
#else
  TempDir dir;
  DaemonOptions options;
  options.binary = SCP_ALLOCCOUNT_PATH;
  DaemonProcess daemon(
      dir,
      {{"refine",
        {{"window_s", 300.0}, {"interval_s", 1.0}, {"min_window_s", 2.0}, {"max_gap_s", 1.0}}}},
      options);
  daemon.start();
  const auto status = daemon.wait_status(
      [](const json& s) { return s.contains("refine") && s["refine"]["fits"].get<int>() >= 4; },
      Seconds(60));
  ASSERT_TRUE(status.has_value()) << daemon.stderr_text();
  std::printf("STATUS loop %s refine %s\n", (*status)["loop"]["allocations"].dump().c_str(),
              (*status)["refine"].dump().c_str());
  ASSERT_TRUE((*status)["loop"].contains("allocations")) << "not the counting build";
  EXPECT_EQ((*status)["loop"]["allocations"].get<std::uint64_t>(), 0U);
  EXPECT_GE((*status)["refine"]["fits"].get<int>(), 4);
#endif
}

}  // namespace
}  // namespace scp::test

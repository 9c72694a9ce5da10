// The batch run of the paper's experiment (200 s at 1 kHz through the daemon's loop) as a multiple
// of real time, with and without recording every cycle to CSV (the loop alone: refinement off),
// and with the output-error refinement as config/paper.yaml ships it (a fit every 10 s), inline
// (--jobs 1) and on one worker thread per core beside the loop (--jobs default).

#include <benchmark/benchmark.h>

#include <filesystem>
#include <string>

#include "daemon/batch/batch_run.hpp"
#include "daemon/config/daemon_config.hpp"

namespace {

void run(benchmark::State& state, bool record, bool refine = false, unsigned jobs = 1) {
  auto cfg = scp::config::load_config_file(std::string(SCP_SOURCE_DIR) + "/config/paper.yaml");
  cfg.refine.enabled = refine;
  scp::daemon::BatchOptions options;
  options.duration_s = 200.0;
  options.jobs = jobs;
  const auto csv = std::filesystem::temp_directory_path() / "scp-bench-batch.csv";
  if (record) options.record_path = csv.string();
  double loop_seconds = 0.0;
  for (auto _ : state) {
    const auto summary = scp::daemon::run_batch(cfg, options);
    loop_seconds += summary["t"].get<double>();
    benchmark::DoNotOptimize(summary);
  }
  // Simulated seconds per wall second: the speed as a multiple of real time.
  state.counters["x_realtime"] = benchmark::Counter(loop_seconds, benchmark::Counter::kIsRate);
  if (record) std::filesystem::remove(csv);
}

void BM_PaperBatch200s(benchmark::State& state) {
  run(state, false);
}
void BM_PaperBatch200sRecorded(benchmark::State& state) {
  run(state, true);
}
void BM_PaperBatch200sRefined(benchmark::State& state) {
  run(state, false, true);
}
void BM_PaperBatch200sRefinedJobs(benchmark::State& state) {
  run(state, false, true, /*jobs=*/0);
}

BENCHMARK(BM_PaperBatch200s)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();
BENCHMARK(BM_PaperBatch200sRecorded)->Unit(benchmark::kMillisecond)->Iterations(2)->UseRealTime();
BENCHMARK(BM_PaperBatch200sRefined)->Unit(benchmark::kMillisecond)->Iterations(1)->UseRealTime();
BENCHMARK(BM_PaperBatch200sRefinedJobs)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();

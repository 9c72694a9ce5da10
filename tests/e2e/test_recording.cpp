// Issue 10, recording in service mode: the running daemon writes rotating CSV files from a
// thread beside the loop; rows carry the wall-clock time; a full disk (a small tmpfs) costs rows,
// counted in STATUS, never the loop's period.

#include <sys/mount.h>
#include <zlib.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <sstream>

#include "tests/e2e/e2e_util.hpp"
#include "tests/support/gunzip.hpp"
#include "tests/support/recording_files.hpp"

namespace scp::test {
namespace {

std::size_t column(const std::vector<std::string>& header, const std::string& name) {
  const auto it = std::find(header.begin(), header.end(), name);
  return it == header.end() ? header.size() : static_cast<std::size_t>(it - header.begin());
}

TEST(Recording, RotatingFilesWithWallClockTime) {
  TempDir dir;
  const std::string rec = dir.file("rec");
  std::filesystem::create_directory(rec);
  DaemonProcess daemon(
      dir, {{"actuator", {{"name", "bench-a"}}},
            {"refine", {{"enabled", false}}},
            {"recording", {{"directory", rec}, {"rotate_interval_s", 1.0}, {"keep_files", 3}}}});
  daemon.start();
  sleep_s(4.5);
  const json st = daemon.status();
  ASSERT_TRUE(st.contains("recording")) << st.dump();
  daemon.signal(SIGTERM);
  ASSERT_EQ(daemon.wait_exit(Seconds(10)), std::optional<int>(0)) << daemon.stderr_text();

  const auto files = files_ending(rec, ".csv");
  ASSERT_GE(files.size(), 2u) << "no rotation after 4.5 s at rotate_interval_s 1";
  EXPECT_LE(files.size(), 3u) << "keep_files 3 not applied";
  for (const auto& f : files)
    EXPECT_EQ(std::filesystem::path(f).filename().string().rfind("bench-a-", 0), 0u) << f;

  // Rows' UTC times increase across the files; every file has the header.
  std::int64_t last_ns = 0;
  std::size_t rows = 0;
  for (const auto& f : files) {
    std::istringstream in(read_text(f));
    std::string line;
    ASSERT_TRUE(std::getline(in, line));
    const auto header = split_csv(line);
    ASSERT_EQ(header.at(0), "t") << f;
    const std::size_t ns_col = column(header, "unix_ns");
    const std::size_t src_col = column(header, "xdot_source");
    const std::size_t since_col = column(header, "V_since");
    ASSERT_LT(ns_col, header.size()) << line;
    ASSERT_LT(src_col, header.size()) << line;
    ASSERT_LT(since_col, header.size()) << line;
    while (std::getline(in, line)) {
      const auto fields = split_csv(line);
      ASSERT_EQ(fields.size(), header.size()) << f << ": " << line;
      const std::int64_t ns = std::stoll(fields[ns_col]);
      EXPECT_GT(ns, last_ns) << f << ": UTC time not increasing at " << line;
      last_ns = ns;
      EXPECT_EQ(fields[src_col], "measured");
      // The simulated driver's voltage switches at the samples: the whole interval.
      EXPECT_EQ(fields[since_col], "") << f << ": " << line;
      ++rows;
    }
  }
  EXPECT_GT(rows, 1000u);

  // Replaying the files: e2e.RecordReplay (test_record_replay.cpp).
}

// The loop at SCHED_FIFO as in service (the tmpfs mount needs root, which may set it), recording
// into `directory`.
json recording_daemon_config(const std::string& directory) {
  return {{"loop", {{"realtime", {{"priority", 50}}}}},
          {"refine", {{"enabled", false}}},
          {"recording", {{"directory", directory}, {"rotate_interval_s", 0.0}}}};
}

double overrun_share(const json& status) {
  const auto cycles = loop_count(status, "cycles");
  return cycles == 0
             ? 1.0
             : static_cast<double>(loop_count(status, "overruns")) / static_cast<double>(cycles);
}

// A full filesystem under recording.directory: the loop keeps its period, the daemon keeps
// running and STATUS counts the rows it could not hand over.
TEST(Recording, FullDiskDropsCountedRowsAndKeepsThePeriod) {
  TempDir dir, baseline_dir;
  const std::string rec = dir.file("tiny");
  std::filesystem::create_directory(rec);
  if (::mount("tmpfs", rec.c_str(), "tmpfs", 0, "size=64k") != 0) {
    const char* ci = std::getenv("CI");
    if (ci != nullptr && std::string(ci) == "true")
      FAIL() << "cannot mount a tmpfs (needs root / CAP_SYS_ADMIN): " << std::strerror(errno);
    GTEST_SKIP() << "cannot mount a tmpfs: " << std::strerror(errno);
  }
  struct Unmount {
    std::string path;
    ~Unmount() { ::umount2(path.c_str(), MNT_DETACH); }
  } unmount{rec};
  // The same daemon recording onto a disk with room, at the same time: what the full disk costs
  // the loop is the difference, whatever the machine's load costs both (a loaded CI machine gave
  // a daemon at SCHED_FIFO 6.5 % overruns with a disk that had nothing to do with it).
  const std::string baseline_rec = baseline_dir.file("rec");
  std::filesystem::create_directory(baseline_rec);
  DaemonProcess baseline(baseline_dir, recording_daemon_config(baseline_rec));
  DaemonProcess daemon(dir, recording_daemon_config(rec));
  baseline.start();
  daemon.start();
  // 64 KiB hold about 200 rows (0.2 s); the ring holds 16384 more (16 s at 1 kHz).
  const auto dropping = daemon.wait_status(
      [](const json& s) {
        return s.contains("recording") && s["recording"].value("dropped_rows", 0) > 1000;
      },
      Seconds(40));
  ASSERT_TRUE(dropping) << "no dropped rows counted: " << daemon.status().dump()
                        << daemon.stderr_text();
  const json st = *dropping;
  const json baseline_st = baseline.status();
  EXPECT_EQ(st.value("state", ""), "running") << st.dump();
  EXPECT_TRUE(contains(daemon.stderr_text(), "recording: cannot write")) << daemon.stderr_text();
  EXPECT_EQ(baseline_st["recording"].value("dropped_rows", -1), 0) << baseline_st.dump();
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  // An instrumented 1 kHz loop is several times slower: 5.4 % overruns measured under ASan on a
  // loaded 2-core VM, which says nothing about the disk. The normal build checks the period.
  return;
#endif
  // The period held: cycles follow loop time (1 kHz), and overruns are no more common than
  // beside a disk with room. A loop that waited on the disk would overrun at every write.
  const double uptime = num(st, "uptime_s");
  EXPECT_GT(static_cast<double>(loop_count(st, "cycles")), 0.9 * uptime * 1000.0) << st.dump();
  std::printf("[ figures ] overruns: %.2f %% with the disk full, %.2f %% beside a disk with room\n",
              100.0 * overrun_share(st), 100.0 * overrun_share(baseline_st));
  EXPECT_LT(overrun_share(st), 2.0 * overrun_share(baseline_st) + 0.01)
      << st.dump() << "\nbaseline: " << baseline_st.dump();
}

json replay(const DaemonProcess& daemon, const std::string& what) {
  const ProcessResult r = run_process({estimatord_path(), "--config", daemon.config_path(),
                                       "--offline", "--json", "--replay", what},
                                      Seconds(120));
  EXPECT_EQ(r.exit_code, 0) << r.err << r.out;
  return r.exit_code == 0 ? json::parse(r.out) : json::object();
}

// recording.compress gzip: the rotated files become .csv.gz (the current one stays plain), no
// temporary file is left, and the directory replays as it is to the very θ̂ of the same rows
// uncompressed, which is the θ̂ the live run recorded in its last row.
TEST(Recording, CompressedRecordingReplaysToTheSameEstimate) {
  TempDir dir;
  const std::string rec = dir.file("rec");
  std::filesystem::create_directory(rec);
  DaemonProcess daemon(dir, {{"actuator", {{"name", "bench-z"}}},
                             {"refine", {{"enabled", false}}},
                             {"recording",
                              {{"directory", rec},
                               {"rotate_interval_s", 1.0},
                               {"keep_files", 0},
                               {"compress", "gzip"}}}});
  daemon.start();
  // At least 3 files rotated and compressed. The compressor runs at nice 19: on a loaded machine
  // it may trail the 1 s rotation by seconds (measured under `stress -c 2`: 1 file after 6 s),
  // so this waits for them instead of sleeping a fixed time.
  for (int i = 0; i < 600 && files_ending(rec, ".csv.gz").size() < 3; ++i) sleep_s(0.1);
  daemon.signal(SIGTERM);
  ASSERT_EQ(daemon.wait_exit(Seconds(10)), std::optional<int>(0)) << daemon.stderr_text();

  const auto packed = files_ending(rec, ".csv.gz");
  ASSERT_GE(packed.size(), 3u) << "rotated files not compressed: " << daemon.stderr_text();
  EXPECT_GE(files_ending(rec, ".csv").size(), 1u) << "the last file stays plain";
  EXPECT_TRUE(files_ending(rec, ".tmp").empty());

  // The same recording uncompressed, beside it.
  const std::string plain = dir.file("plain");
  std::filesystem::create_directory(plain);
  for (const auto& f : packed) {
    const std::string name = std::filesystem::path(f).filename().string();
    write_text(plain + "/" + name.substr(0, name.size() - 3), gunzip(f));
  }
  for (const auto& f : files_ending(rec, ".csv"))
    std::filesystem::copy_file(f, plain + "/" + std::filesystem::path(f).filename().string());

  const json from_packed = replay(daemon, rec);
  const json from_plain = replay(daemon, plain);
  ASSERT_TRUE(from_packed.contains("theta_hat")) << from_packed.dump();
  ASSERT_TRUE(from_plain.contains("theta_hat")) << from_plain.dump();
  EXPECT_EQ(from_packed["replay"]["rows"], from_plain["replay"]["rows"]);
  EXPECT_EQ(from_packed["replay"]["files"], from_plain["replay"]["files"]);
  EXPECT_GT(from_packed["replay"]["rows"].get<std::size_t>(), 1000u);
  // The live θ̂ of the last row.
  std::istringstream last(read_text(files_ending(plain, ".csv").back()));
  std::string line;
  std::string last_row;
  std::getline(last, line);
  const auto header = split_csv(line);
  while (std::getline(last, line))
    if (!line.empty() && line[0] != '#') last_row = line;
  const auto fields = split_csv(last_row);
  for (std::size_t i = 0; i < 6; ++i) {
    const double a = from_packed["theta_hat"][i].get<double>();
    EXPECT_EQ(a, from_plain["theta_hat"][i].get<double>()) << "theta_hat" << i + 1;
    const std::size_t col = column(header, "theta_hat" + std::to_string(i + 1));
    ASSERT_LT(col, fields.size());
    EXPECT_EQ(a, std::stod(fields[col])) << "theta_hat" << i + 1 << " differs from the live run";
  }
}

}  // namespace
}  // namespace scp::test

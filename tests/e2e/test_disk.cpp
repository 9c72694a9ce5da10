// Issue 5, item 12: a full disk while writing state or a recording. The daemon must say which
// file could not be written and why, keep the previous checkpoint intact, and keep running.

#include <sys/mount.h>

#include <cerrno>
#include <cstring>
#include <fstream>

#include "tests/e2e/e2e_util.hpp"

namespace scp::test {
namespace {

// A 16 KiB tmpfs, unmounted at the end of the test (after the daemon is gone: declare it first).
class TinyTmpfs {
 public:
  explicit TinyTmpfs(const std::string& path) : path_(path) {
    std::filesystem::create_directories(path);
    mounted_ = ::mount("tmpfs", path.c_str(), "tmpfs", 0, "size=16k,mode=0755") == 0;
    if (!mounted_) error_ = std::strerror(errno);
  }
  ~TinyTmpfs() {
    if (mounted_) ::umount2(path_.c_str(), MNT_DETACH);
  }
  bool mounted() const { return mounted_; }
  const std::string& error() const { return error_; }
  // Writes until ENOSPC; returns the bytes written.
  std::size_t fill() const {
    std::ofstream out(path_ + "/filler", std::ios::binary);
    const std::string block(512, 'x');
    std::size_t written = 0;
    while (out.write(block.data(), static_cast<std::streamsize>(block.size())) && out.flush()) {
      written += block.size();
      if (written > (1u << 20)) break;  // not a tiny tmpfs after all
    }
    return written;
  }

 private:
  std::string path_;
  bool mounted_ = false;
  std::string error_;
};

TEST(Disk, FullDiskDuringCheckpointKeepsThePreviousStateAndRuns) {
  TempDir dir;
  TinyTmpfs disk(dir.file("state"));
  if (!disk.mounted())
    GTEST_SKIP() << "cannot mount a tmpfs here (" << disk.error() << "); needs root";
  DaemonProcess daemon(dir, {{"state", {{"checkpoint_interval_s", 0.2}}}});
  daemon.start();
  const auto deadline = std::chrono::steady_clock::now() + Seconds(10);
  while (!std::filesystem::exists(daemon.state_file()) &&
         std::chrono::steady_clock::now() < deadline) {
    sleep_s(0.05);
  }
  ASSERT_TRUE(std::filesystem::exists(daemon.state_file())) << daemon.stderr_text();
  ASSERT_LT(disk.fill(), 1u << 20) << "the tmpfs did not fill up";
  sleep_s(0.3);  // a checkpoint may have been half-way when the disk filled
  const std::string previous = read_text(daemon.state_file());
  const auto log_before = daemon.stderr_text().size();
  sleep_s(1.5);  // several checkpoint attempts onto the full disk

  const std::string log = daemon.stderr_text().substr(log_before);
  EXPECT_TRUE(contains(log, "checkpoint failed")) << log;
  EXPECT_TRUE(contains(log, "No space left on device")) << log;
  EXPECT_TRUE(contains(log, daemon.state_file())) << "the message must name the file:\n" << log;
  EXPECT_EQ(read_text(daemon.state_file()), previous) << "the previous checkpoint was damaged";
  const json saved = json::parse(previous);  // complete JSON, not truncated
  EXPECT_EQ(saved.value("format", ""), "scp-estimator-state");
  EXPECT_EQ(daemon.status().value("state", ""), "running");
  EXPECT_TRUE(daemon.running());
}

TEST(Disk, OfflineRecordOntoAFullDiskFailsNamingTheFile) {
  TempDir dir;
  TinyTmpfs disk(dir.file("full"));
  if (!disk.mounted())
    GTEST_SKIP() << "cannot mount a tmpfs here (" << disk.error() << "); needs root";
  disk.fill();
  write_config(dir.file("config.yaml"), base_config(dir.path()));
  const std::string record = dir.file("full") + "/run.csv";
  const ProcessResult r = run_process({estimatord_path(), "--config", dir.file("config.yaml"),
                                       "--offline", "--duration", "5", "--record", record},
                                      Seconds(60));
  EXPECT_EQ(r.signal, 0) << "crashed with signal " << r.signal << ":\n" << r.err;
  EXPECT_NE(r.exit_code, 0) << "a recording that could not be written must fail the run\n" << r.out;
  EXPECT_NE(r.exit_code, -1);
  EXPECT_TRUE(contains(r.err, record)) << "the message must name the file:\n" << r.err;
  EXPECT_TRUE(contains(r.err, "No space left on device")) << r.err;
}

}  // namespace
}  // namespace scp::test

// recording.compress gzip: the atomic gzip writer and the recorder's rotation, compression and
// retention together (the e2e test Recording.CompressedRecordingReplaysToTheSameEstimate runs the
// daemon).

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <zlib.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

#include "daemon/outputs/recording/compressor.hpp"
#include "daemon/outputs/recording/recorder.hpp"
#include "drivers/replay/csv_trace.hpp"
#include "tests/support/gunzip.hpp"

namespace scp::daemon {
namespace {

namespace fs = std::filesystem;

class TempDirectory {
 public:
  TempDirectory() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path_ = ::testing::TempDir() + "scp_compress_" + info->name();
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDirectory() { fs::remove_all(path_); }
  std::string file(const std::string& name) const { return path_ + "/" + name; }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

std::string some_text() {
  std::string text;
  for (int i = 0; i < 100000; ++i) text += std::to_string(i * 0.001) + ",1.5e-6,25.25\n";
  return text;
}

TEST(Compressor, GzipFileReplacesThePlainFileWithTheSameBytes) {
  TempDirectory dir;
  const std::string path = dir.file("a.csv");
  const std::string text = some_text();
  std::ofstream(path) << text;
  ::chmod(path.c_str(), 0640);
  ASSERT_TRUE(gzip_file(path, Z_DEFAULT_COMPRESSION));
  EXPECT_FALSE(fs::exists(path));
  EXPECT_FALSE(fs::exists(path + ".gz.tmp"));
  ASSERT_TRUE(fs::exists(path + ".gz"));
  EXPECT_EQ(test::gunzip(path + ".gz"), text);
  EXPECT_LT(fs::file_size(path + ".gz"), text.size() / 2);
  struct stat st {};
  ASSERT_EQ(::stat((path + ".gz").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0640u) << "the compressed file keeps the recording's mode";
}

TEST(Compressor, CancelledCompressionKeepsThePlainFileAndNoTemporary) {
  TempDirectory dir;
  const std::string path = dir.file("a.csv");
  std::ofstream(path) << some_text();
  const std::atomic<bool> cancel{true};
  EXPECT_FALSE(gzip_file(path, Z_DEFAULT_COMPRESSION, &cancel));
  EXPECT_TRUE(fs::exists(path));
  EXPECT_FALSE(fs::exists(path + ".gz"));
  EXPECT_FALSE(fs::exists(path + ".gz.tmp"));
}

TEST(Compressor, MissingFileIsAnErrorNamingIt) {
  TempDirectory dir;
  try {
    gzip_file(dir.file("gone.csv"), 1);
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(dir.file("gone.csv")), std::string::npos) << e.what();
  }
}

std::size_t count_with(const std::string& directory, const std::string& tail) {
  std::size_t n = 0;
  for (const auto& entry : fs::directory_iterator(directory)) {
    const std::string name = entry.path().filename().string();
    if (name.size() >= tail.size() &&
        name.compare(name.size() - tail.size(), tail.size(), tail) == 0)
      ++n;
  }
  return n;
}

// Rows pushed as the loop would; tiny files so that many rotations happen.
void record_rows(Recorder& recorder, RecordRing& ring, int count, double t0) {
  for (int i = 0; i < count; ++i) {
    RecordRow row;
    row.t = t0 + 0.001 * i;
    row.x = 1e-6 * i;
    row.temperature = 25.0;
    row.voltage = 1.0;
    row.unix_ns = 1'700'000'000'000'000'000 + i;
    row.state = static_cast<std::uint8_t>(RunState::running);
    while (!ring.try_push(row)) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  while (ring.size_approx() > 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  (void)recorder;
}

TEST(Compressor, RecorderCompressesRotatedFilesAndRetentionCountsThem) {
  TempDirectory dir;
  auto ring = std::make_unique<RecordRing>();
  config::RecordingSettings settings;
  settings.directory = dir.path();
  settings.rotate_size_mib = 0.05;  // ~130 rows of ~400 bytes
  settings.rotate_interval_s = 0.0;
  settings.keep_files = 4;
  settings.compress = config::Compression::gzip;
  Recorder recorder(settings, "bench", *ring);
  recorder.start();
  record_rows(recorder, *ring, 2000, 0.0);
  recorder.wait_compressed();
  const std::string current = recorder.current_file();
  recorder.finish();

  EXPECT_EQ(count_with(dir.path(), ".csv"), 1u) << "only the file being written stays plain";
  EXPECT_TRUE(fs::exists(current));
  EXPECT_EQ(count_with(dir.path(), ".csv.gz"), 3u) << "keep_files 4: three compressed + current";
  EXPECT_EQ(count_with(dir.path(), ".tmp"), 0u);
  // Older files may be deleted by the retention before their turn (skipped, not compressed).
  EXPECT_GE(recorder.files_compressed(), 3u);
  // The kept files replay as one trace, the last row the last recorded.
  const auto trace = drivers::replay::load_traces({dir.path()});
  EXPECT_EQ(trace.files.size(), 4u);
  EXPECT_DOUBLE_EQ(trace.rows.back().t, 1.999);
}

TEST(Compressor, PlainFilesOfAnEarlierRunAreCompressedAtStart) {
  TempDirectory dir;
  std::ofstream(dir.file("bench-20261101T000000.000Z.csv")) << "t,x,xdot,T,V\n0,0,0,25,0\n";
  std::ofstream(dir.file("bench-20261101T000001.000Z.csv.gz.tmp")) << "interrupted";
  std::ofstream(dir.file("other-20261101T000000.000Z.csv")) << "another actuator's";
  auto ring = std::make_unique<RecordRing>();
  config::RecordingSettings settings;
  settings.directory = dir.path();
  settings.keep_files = 0;
  settings.compress = config::Compression::gzip;
  Recorder recorder(settings, "bench", *ring);
  recorder.start();
  recorder.wait_compressed();
  recorder.finish();
  EXPECT_TRUE(fs::exists(dir.file("bench-20261101T000000.000Z.csv.gz")));
  EXPECT_FALSE(fs::exists(dir.file("bench-20261101T000000.000Z.csv")));
  EXPECT_FALSE(fs::exists(dir.file("bench-20261101T000001.000Z.csv.gz.tmp")));
  EXPECT_TRUE(fs::exists(dir.file("other-20261101T000000.000Z.csv"))) << "not this actuator's";
}

}  // namespace
}  // namespace scp::daemon

// Compressed recordings (recording.compress: gzip) replay as they are: the same rows as the plain
// file, the same error messages with line numbers, and a clear error naming a corrupt or truncated
// file.

#include <gtest/gtest.h>
#include <zlib.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "drivers/replay/csv_trace.hpp"

namespace scp::drivers::replay {
namespace {

class TempDirectory {
 public:
  TempDirectory() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path_ = ::testing::TempDir() + "scp_gz_" + info->name();
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~TempDirectory() { std::filesystem::remove_all(path_); }
  std::string file(const std::string& name) const { return path_ + "/" + name; }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

void write_plain(const std::string& path, const std::string& text) {
  std::ofstream(path, std::ios::binary) << text;
}

void write_gzip(const std::string& path, const std::string& text) {
  gzFile f = gzopen(path.c_str(), "wb");
  ASSERT_NE(f, nullptr);
  ASSERT_EQ(gzwrite(f, text.data(), static_cast<unsigned>(text.size())),
            static_cast<int>(text.size()));
  ASSERT_EQ(gzclose(f), Z_OK);
}

std::string rows(double t0, int n) {
  std::string out = "t,x,xdot,T,V,theta_hat1\n";
  for (int i = 0; i < n; ++i) {
    out += std::to_string(t0 + 0.001 * i) + "," + std::to_string(1e-6 * i) + ",0.5,25.5," +
           std::to_string(0.01 * (i % 300)) + ",1\n";
  }
  return out;
}

std::string error_of(const std::string& path) {
  try {
    load_trace(path);
  } catch (const TraceError& e) {
    return e.what();
  }
  return "";
}

TEST(GzipTrace, SameRowsAsThePlainFile) {
  TempDirectory dir;
  const std::string text = rows(10.0, 5000);
  write_plain(dir.file("a.csv"), text);
  write_gzip(dir.file("b.csv.gz"), text);
  const Trace plain = load_trace(dir.file("a.csv"));
  const Trace packed = load_trace(dir.file("b.csv.gz"));
  ASSERT_EQ(plain.rows.size(), 5000u);
  ASSERT_EQ(packed.rows.size(), plain.rows.size());
  for (std::size_t i = 0; i < plain.rows.size(); ++i) {
    EXPECT_EQ(packed.rows[i].t, plain.rows[i].t);
    EXPECT_EQ(packed.rows[i].x, plain.rows[i].x);
    EXPECT_EQ(packed.rows[i].voltage, plain.rows[i].voltage);
  }
  EXPECT_EQ(packed.period, plain.period);
  EXPECT_EQ(packed.files, std::vector<std::string>{dir.file("b.csv.gz")});
}

TEST(GzipTrace, ErrorsNameTheFileAndTheLineOfTheDecompressedText) {
  TempDirectory dir;
  write_gzip(dir.file("bad.csv.gz"), "t,x,xdot,T,V\n0,0,0,25,0\n0.001,0,0,25,oops\n");
  const std::string what = error_of(dir.file("bad.csv.gz"));
  EXPECT_EQ(what.rfind(dir.file("bad.csv.gz") + ":3: column 'V' (field 5): cannot parse 'oops'", 0),
            0u)
      << what;
}

TEST(GzipTrace, TruncatedFileIsRefusedNamingIt) {
  TempDirectory dir;
  write_gzip(dir.file("cut.csv.gz"), rows(0.0, 20000));
  const auto size = std::filesystem::file_size(dir.file("cut.csv.gz"));
  std::filesystem::resize_file(dir.file("cut.csv.gz"), size / 2);
  const std::string what = error_of(dir.file("cut.csv.gz"));
  EXPECT_EQ(what.rfind(dir.file("cut.csv.gz") + ": corrupt or truncated gzip data after line ", 0),
            0u)
      << what;
  EXPECT_NE(what.find("zcat"), std::string::npos) << what;
}

TEST(GzipTrace, CorruptedBytesAreRefusedNamingTheFile) {
  TempDirectory dir;
  const std::string path = dir.file("flip.csv.gz");
  write_gzip(path, rows(0.0, 20000));
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  // Flip bits in the middle of the deflate data: either the stream is invalid or the CRC-32 at
  // the end does not match; both must be an error, never rows read as valid.
  for (std::size_t i = bytes.size() / 2; i < bytes.size() / 2 + 8; ++i) bytes[i] ^= 0x5a;
  write_plain(path, bytes);
  const std::string what = error_of(path);
  EXPECT_EQ(what.rfind(path + ": corrupt or truncated gzip data", 0), 0u) << what;
}

TEST(GzipTrace, PlainDataUnderAGzNameIsRefused) {
  TempDirectory dir;
  write_plain(dir.file("plain.csv.gz"), rows(0.0, 10));
  const std::string what = error_of(dir.file("plain.csv.gz"));
  EXPECT_EQ(what.rfind(dir.file("plain.csv.gz") + ": not gzip data", 0), 0u) << what;
}

TEST(GzipTrace, DirectoryMixesPlainAndCompressedInNameOrder) {
  TempDirectory dir;
  // The daemon's names: a-<UTC>.csv; the older ones compressed, the newest plain. One recording
  // is there twice (a crash between the rename and the unlink): taken once.
  write_gzip(dir.file("a-20261123T100000.000Z.csv.gz"), rows(0.0, 100));
  write_gzip(dir.file("a-20261123T100001.000Z.csv.gz"), rows(1.0, 100));
  write_plain(dir.file("a-20261123T100001.000Z.csv"), rows(1.0, 100));
  write_plain(dir.file("a-20261123T100002.000Z.csv"), rows(2.0, 100));
  write_plain(dir.file("a-20261123T100002.000Z.csv.gz.tmp"), "half written");
  const Trace trace = load_traces({dir.path()});
  EXPECT_EQ(trace.rows.size(), 300u);
  ASSERT_EQ(trace.files.size(), 3u);
  EXPECT_EQ(trace.files[0], dir.file("a-20261123T100000.000Z.csv.gz"));
  EXPECT_EQ(trace.files[1], dir.file("a-20261123T100001.000Z.csv"));
  EXPECT_EQ(trace.files[2], dir.file("a-20261123T100002.000Z.csv"));
}

}  // namespace
}  // namespace scp::drivers::replay

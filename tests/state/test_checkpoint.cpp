#include <gtest/gtest.h>
#include <signal.h>
#include <sys/mount.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>

#include "daemon/service/state/checkpoint.hpp"

namespace scp::daemon::state {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

Checkpoint sample_checkpoint() {
  Checkpoint c;
  c.theta_hat = {1247.0, 0.8, 1813.0, 0.1, 0.0594059, 1.1001100};
  // SPD, with the mechanical block's tiny information (the regressors are ~1e-3 m).
  c.info_mech = {4e-6, 1e-7, 2e-7, 0.0,   //
                 1e-7, 3e-6, 0.0,  1e-8,  //
                 2e-7, 0.0,  5e-6, 0.0,   //
                 0.0,  1e-8, 0.0,  2e-6};
  c.info_thermal = {12.5, -0.75, -0.75, 3.0};
  c.eps2_mean = {1.5e-12, 2.5e-4};
  c.t = 123.456;
  c.driver = "sim";
  c.wall_time_unix = 1'700'000'000;
  return c;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void spit(const fs::path& p, const std::string& text) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out << text;
}

// Independent FNV-1a over the payload with the reference constants, to re-sign edited files.
std::string sign(json j) {
  j.erase("checksum");
  std::uint64_t h = 14695981039346656037ULL;
  for (unsigned char ch : j.dump()) {
    h ^= ch;
    h *= 1099511628211ULL;
  }
  char buf[32];
  std::snprintf(buf, sizeof(buf), "fnv1a64:%016llx", static_cast<unsigned long long>(h));
  j["checksum"] = buf;
  return j.dump(2);
}

class CheckpointTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const char* base = std::getenv("TMPDIR");
    dir_ = fs::path(base ? base : "/tmp") /
           ("scp-state-test-" + std::to_string(getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    path_ = (dir_ / "state.json").string();
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::vector<std::string> tmp_files() const {
    std::vector<std::string> out;
    for (const auto& e : fs::directory_iterator(dir_)) {
      if (e.path().filename().string().find(".tmp.") != std::string::npos) out.push_back(e.path());
    }
    return out;
  }

  // Writes `mutate(valid json)` re-signed and expects the load to fail with `needle` in the
  // warning.
  void expect_rejected(const std::function<void(json&)>& mutate, const std::string& needle,
                       bool resign = true) {
    save_checkpoint(path_, sample_checkpoint());
    json j = json::parse(slurp(path_));
    mutate(j);
    spit(path_, resign ? sign(j) : j.dump(2));
    std::string warning;
    EXPECT_FALSE(load_checkpoint(path_, warning).has_value());
    EXPECT_NE(warning.find(needle), std::string::npos) << warning;
    EXPECT_NE(warning.find("starting cold"), std::string::npos) << warning;
  }

  fs::path dir_;
  std::string path_;
};

TEST(Fnv1a, ReferenceVectors) {
  // Published FNV-1a 64-bit test vectors.
  EXPECT_EQ(fnv1a64(""), 0xcbf29ce484222325ULL);
  EXPECT_EQ(fnv1a64("a"), 0xaf63dc4c8601ec8cULL);
  EXPECT_EQ(fnv1a64("foobar"), 0x85944171f73967e8ULL);
}

TEST_F(CheckpointTest, RoundTripIsExact) {
  const Checkpoint c = sample_checkpoint();
  save_checkpoint(path_, c);
  std::string warning;
  const auto loaded = load_checkpoint(path_, warning);
  ASSERT_TRUE(loaded.has_value()) << warning;
  EXPECT_TRUE(warning.empty());
  EXPECT_EQ(loaded->theta_hat, c.theta_hat);
  EXPECT_EQ(loaded->info_mech, c.info_mech);
  EXPECT_EQ(loaded->info_thermal, c.info_thermal);
  EXPECT_EQ(loaded->eps2_mean, c.eps2_mean);
  EXPECT_EQ(loaded->t, c.t);
  EXPECT_EQ(loaded->driver, c.driver);
  EXPECT_EQ(loaded->wall_time_unix, c.wall_time_unix);
  EXPECT_TRUE(tmp_files().empty());
}

TEST_F(CheckpointTest, FileFormatIsDocumented) {
  save_checkpoint(path_, sample_checkpoint());
  const json j = json::parse(slurp(path_));
  EXPECT_EQ(j.at("format"), "scp-estimator-state");
  EXPECT_EQ(j.at("version"), 1);
  EXPECT_EQ(j.at("theta_hat").size(), 6U);
  EXPECT_EQ(j.at("info_mech").size(), 16U);
  // The checksum is FNV-1a over the compact dump of the rest, computed here independently.
  EXPECT_EQ(sign(j), j.dump(2));
}

TEST_F(CheckpointTest, OverwriteReplacesThePreviousFile) {
  Checkpoint c = sample_checkpoint();
  save_checkpoint(path_, c);
  c.t = 999.0;
  save_checkpoint(path_, c);
  std::string warning;
  EXPECT_EQ(load_checkpoint(path_, warning)->t, 999.0);
}

TEST_F(CheckpointTest, MissingFile) {
  std::string warning;
  EXPECT_FALSE(load_checkpoint(path_, warning).has_value());
  EXPECT_NE(warning.find("no checkpoint at " + path_), std::string::npos) << warning;
  EXPECT_NE(warning.find("starting cold"), std::string::npos) << warning;
}

TEST_F(CheckpointTest, UnreadableFile) {
  fs::create_directories(path_);  // a directory where the file should be
  std::string warning;
  EXPECT_FALSE(load_checkpoint(path_, warning).has_value());
  EXPECT_NE(warning.find(path_), std::string::npos) << warning;
  EXPECT_NE(warning.find("starting cold"), std::string::npos) << warning;
}

TEST_F(CheckpointTest, TruncatedFile) {
  save_checkpoint(path_, sample_checkpoint());
  const std::string full = slurp(path_);
  for (std::size_t keep : {std::size_t{0}, std::size_t{1}, full.size() / 2, full.size() - 3}) {
    spit(path_, full.substr(0, keep));
    std::string warning;
    EXPECT_FALSE(load_checkpoint(path_, warning).has_value()) << keep;
    EXPECT_NE(warning.find("truncated or not valid JSON"), std::string::npos) << warning;
  }
}

TEST_F(CheckpointTest, BadChecksum) {
  // A digit changed without re-signing: a corrupted or hand-edited file.
  expect_rejected([](json& j) { j["theta_hat"][0] = 1248.0; }, "checksum does not match", false);
  expect_rejected([](json& j) { j.erase("checksum"); }, "no checksum", false);
}

TEST_F(CheckpointTest, WrongFormatOrVersion) {
  expect_rejected([](json& j) { j["version"] = 2; }, "version 2");
  expect_rejected([](json& j) { j["format"] = "something-else"; },
                  "not an scp-estimator state file");
}

TEST_F(CheckpointTest, NonFiniteOrMissingNumbers) {
  // JSON writers store NaN and Inf as null.
  expect_rejected([](json& j) { j["theta_hat"][3] = nullptr; },
                  "theta_hat[3]' is not a finite number");
  expect_rejected([](json& j) { j["info_thermal"][1] = "x"; }, "info_thermal[1]");
  expect_rejected([](json& j) { j["eps2_mean"] = json::array({1.0}); }, "eps2_mean");
  expect_rejected([](json& j) { j.erase("t"); }, "field 't'");
  expect_rejected([](json& j) { j["t"] = std::numeric_limits<double>::infinity(); }, "field 't'");
  expect_rejected([](json& j) { j.erase("driver"); }, "driver");
  expect_rejected([](json& j) { j["eps2_mean"][0] = -1.0; }, "negative");
}

TEST_F(CheckpointTest, InformationMatricesMustBeSymmetricPositiveDefinite) {
  // Not symmetric.
  expect_rejected(
      [](json& j) {
        j["info_thermal"] = {1.0, 0.5, 0.4, 1.0};
      },
      "info_thermal' is not a symmetric");
  // Symmetric but indefinite: eigenvalues 3 and −1.
  expect_rejected(
      [](json& j) {
        j["info_thermal"] = {1.0, 2.0, 2.0, 1.0};
      },
      "info_thermal' is not a positive definite");
  // Singular (rank 1): positive semidefinite is not enough to invert.
  expect_rejected([](json& j) { j["info_thermal"] = {1.0, 1.0, 1.0, 1.0}; }, "positive definite");
  // All zeros.
  expect_rejected([](json& j) { j["info_mech"] = std::vector<double>(16, 0.0); },
                  "info_mech' is not a positive definite");
  // Negative diagonal entry in the mechanical block.
  expect_rejected([](json& j) { j["info_mech"][5] = -3e-6; },
                  "info_mech' is not a positive definite");
}

TEST_F(CheckpointTest, SaveRefusesNonFiniteValues) {
  Checkpoint c = sample_checkpoint();
  save_checkpoint(path_, c);
  c.info_mech[3] = std::numeric_limits<double>::quiet_NaN();
  try {
    save_checkpoint(path_, c);
    FAIL() << "expected a throw";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("info_mech"), std::string::npos) << e.what();
  }
  std::string warning;
  EXPECT_EQ(load_checkpoint(path_, warning)->info_mech[3], 0.0) << warning;  // previous file intact
}

// A crash mid-write leaves a partial temporary file (and never a partial main file, because the
// main name is only ever replaced by rename): the previous checkpoint still loads.
TEST_F(CheckpointTest, CrashMidWriteKeepsThePreviousCheckpoint) {
  Checkpoint c = sample_checkpoint();
  save_checkpoint(path_, c);
  const std::string good = slurp(path_);
  spit(path_ + ".tmp.999999", good.substr(0, good.size() / 3));
  std::string warning;
  const auto loaded = load_checkpoint(path_, warning);
  ASSERT_TRUE(loaded.has_value()) << warning;
  EXPECT_EQ(loaded->t, c.t);
  // The next save is unaffected by the stale temporary, and removes it (pid 999999 is not
  // running: kill(2) reports ESRCH).
  ASSERT_NE(::kill(999999, 0), 0);
  c.t = 7.0;
  save_checkpoint(path_, c);
  EXPECT_EQ(load_checkpoint(path_, warning)->t, 7.0);
  EXPECT_TRUE(tmp_files().empty());
}

TEST_F(CheckpointTest, UnwritableDirectoryNamesThePathAndLeavesNothing) {
  const std::string missing = (dir_ / "no-such-dir" / "state.json").string();
  try {
    save_checkpoint(missing, sample_checkpoint());
    FAIL() << "expected a throw";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(missing), std::string::npos) << what;
    EXPECT_NE(what.find("errno 2"), std::string::npos) << what;  // ENOENT
  }
}

// Disk full: a tmpfs just big enough for one checkpoint, then filled up. The failing save must
// throw ENOSPC naming the path, keep the previous file and leave no temporary file.
TEST_F(CheckpointTest, DiskFullKeepsThePreviousFileAndLeavesNoTemporary) {
  const fs::path mnt = dir_ / "tiny";
  fs::create_directories(mnt);
  if (mount("tmpfs", mnt.c_str(), "tmpfs", 0, "size=16k") != 0) {
    GTEST_SKIP() << "cannot mount a 16 KiB tmpfs at " << mnt << " (" << std::strerror(errno)
                 << "; needs root/CAP_SYS_ADMIN): disk-full behaviour not tested";
  }
  struct Unmount {
    fs::path p;
    ~Unmount() { umount2(p.c_str(), MNT_DETACH); }
  } unmount{mnt};

  const std::string path = (mnt / "state.json").string();
  Checkpoint c = sample_checkpoint();
  save_checkpoint(path, c);
  // Fill the remaining space.
  {
    std::ofstream filler(mnt / "filler", std::ios::binary);
    const std::string block(1024, 'x');
    for (int i = 0; i < 64 && filler; ++i) filler << block << std::flush;
  }
  c.t = 555.0;
  c.driver = std::string(8000, 'd');  // larger than any page tmpfs still has
  try {
    save_checkpoint(path, c);
    FAIL() << "expected ENOSPC";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(path), std::string::npos) << what;
    EXPECT_NE(what.find("No space left on device"), std::string::npos) << what;
  }
  std::string warning;
  const auto loaded = load_checkpoint(path, warning);
  ASSERT_TRUE(loaded.has_value()) << warning;
  EXPECT_EQ(loaded->t, sample_checkpoint().t);
  for (const auto& e : fs::directory_iterator(mnt)) {
    EXPECT_EQ(e.path().filename().string().find(".tmp."), std::string::npos) << e.path();
  }
}

}  // namespace
}  // namespace scp::daemon::state

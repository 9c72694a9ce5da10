#pragma once
// Writes a test's CSV into the gtest temp dir and removes it afterwards.

#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <string>

namespace scp::drivers::replay::testing {

class TraceFile {
 public:
  explicit TraceFile(const std::string& content) {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path_ = ::testing::TempDir() + "scp_replay_" + info->test_suite_name() + "_" + info->name() +
            "_" + std::to_string(counter_++) + ".csv";
    std::ofstream(path_) << content;
  }
  ~TraceFile() { std::remove(path_.c_str()); }
  TraceFile(const TraceFile&) = delete;
  TraceFile& operator=(const TraceFile&) = delete;
  const std::string& path() const { return path_; }

 private:
  static inline int counter_ = 0;
  std::string path_;
};

}  // namespace scp::drivers::replay::testing

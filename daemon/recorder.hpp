#pragma once
// Writes the loop's RecordRows to CSV on its own thread, so that the loop never touches a file.
// The header starts with t,x,xdot,T,V: a recording can be replayed with --replay as it is.

#include <atomic>
#include <cstdio>
#include <string>
#include <thread>

#include "daemon/loop.hpp"

namespace scp::daemon {

class Recorder {
 public:
  // Opens the file; throws std::runtime_error naming the path and the reason.
  Recorder(const std::string& path, RecordRing& ring);
  ~Recorder();
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  // Drains whatever is left, flushes and closes; throws std::runtime_error when the data could
  // not be written completely (disk full), naming the path.
  void finish();
  std::uint64_t rows_written() const noexcept { return rows_.load(); }

 private:
  void run();
  void write_row(const RecordRow& row);

  std::string path_;
  RecordRing& ring_;
  std::FILE* file_ = nullptr;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> rows_{0};
  std::atomic<int> write_errno_{0};
  std::thread thread_;
};

}  // namespace scp::daemon

#pragma once
// Writes the loop's RecordRows to CSV on its own thread, so that the loop never touches a file.
// The header starts with t,x,xdot,T,V: a recording can be replayed with --replay as it is.

#include <atomic>
#include <chrono>
#include <cstdio>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "daemon/analysis/refine/refined_view.hpp"
#include "daemon/core/loop.hpp"
#include "daemon/outputs/recording/compressor.hpp"

namespace scp::daemon {

// Each refined fit, for the recorder, in the order made: it applies to the rows from its
// fitted_at_t on.
using RefinedRing = rt::SpscRing<refine::RefinedView, 64>;

class Recorder {
 public:
  // Opens the file; throws std::runtime_error naming the path and the reason. `refined` (may be
  // null) brings the refinement's fits; their columns are empty before the first.
  Recorder(const std::string& path, RecordRing& ring, RefinedRing* refined = nullptr);
  // Service mode: rotating files <directory>/<actuator>-<UTC time>.csv (config `recording`). A
  // write error (disk full) never stops the thread: it keeps draining the ring so that the loop
  // never waits, counts the rows it could not write, logs once per file and tries a new file at
  // the next rotation. Opens the first file (throws std::runtime_error naming the directory);
  // the rows are taken from the ring only after start(), so that a recorder replacing another
  // (a reload) can be built, and refused, while the other still drains the ring.
  // With recording.compress gzip, each rotated file is compressed by a thread below this one,
  // and this actuator's plain files left by an earlier run are queued at start().
  Recorder(const config::RecordingSettings& settings, const std::string& actuator,
           RecordRing& ring);
  // Service mode: starts draining the ring. `dropped_marked` is the loop's dropped-row count
  // already marked in an earlier recorder's files (a reload), so that its drops are not marked
  // twice.
  void start(std::uint64_t dropped_marked = 0);
  ~Recorder();
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  // Drains whatever is left, flushes and closes; throws std::runtime_error when the data could
  // not be written completely (disk full), naming the path.
  void finish();
  std::uint64_t rows_written() const noexcept { return rows_.load(); }
  // Service mode: rows lost to write errors (a full disk); approximate by up to one buffer.
  std::uint64_t rows_failed() const noexcept { return rows_failed_.load(); }
  // Service mode: the file being written.
  std::string current_file() const;
  // The loop's dropped rows already marked in the files (valid after finish()).
  std::uint64_t dropped_marked() const noexcept { return dropped_marked_; }
  // Service mode with compression: files compressed so far, and failures (the file kept plain).
  std::uint64_t files_compressed() const noexcept {
    return compressor_ ? compressor_->files_compressed() : 0;
  }
  // Tests: blocks until every rotated file so far has been compressed.
  void wait_compressed() {
    if (compressor_) compressor_->wait_idle();
  }

 private:
  void run();
  void write_row(const RecordRow& row);
  // The latest fit made at or before loop time t.
  void advance_refined(double t);
  void open_file(const std::string& path);
  void rotate();  // service mode: close, open the next file, apply the retention
  void apply_retention();
  // At start with compression: temporary files of an interrupted compression are removed, and
  // this actuator's plain files (but the current one) are queued.
  void compress_leftovers();

  std::string path_;
  RecordRing& ring_;
  RefinedRing* refined_ring_;
  refine::RefinedView refined_{};  // applies to the current row
  refine::RefinedView pending_{};  // popped, made after the current row
  bool has_pending_ = false;
  std::uint64_t dropped_marked_ = 0;  // RecordRow::dropped_before already marked in the file
  std::uint64_t failed_marked_ = 0;   // rows_failed_ already marked
  std::FILE* file_ = nullptr;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> rows_{0};
  std::atomic<int> write_errno_{0};
  std::thread thread_;
  // Service mode only.
  bool rotating_ = false;
  config::RecordingSettings settings_;
  std::string actuator_;
  std::uint64_t bytes_in_file_ = 0;
  std::chrono::steady_clock::time_point file_opened_;
  bool error_logged_ = false;
  bool open_error_logged_ = false;
  std::atomic<std::uint64_t> rows_failed_{0};
  mutable std::mutex file_name_mutex_;
  std::string file_name_;
  std::unique_ptr<Compressor> compressor_;  // recording.compress gzip only
};

}  // namespace scp::daemon

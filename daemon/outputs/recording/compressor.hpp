#pragma once
// Compression of rotated recordings (recording.compress: gzip), on a thread of its own at the
// lowest CPU priority, so that neither the loop nor the recorder draining its ring waits for zlib.

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <thread>

namespace scp::daemon {

// Writes `path`.gz from `path` without ever losing a row to a crash: the data go to
// `path`.gz.tmp, which is synced and renamed to `path`.gz (the directory synced too); only then
// is `path` deleted. At any instant the rows are in `path`, in `path`.gz, or in both. Returns
// false when `cancel` became true on the way (the temporary file is removed, `path` kept).
// Throws std::runtime_error naming the file and the reason (the temporary file removed, `path`
// kept). `level` is zlib's (1 fastest .. 9 smallest).
bool gzip_file(const std::string& path, int level, const std::atomic<bool>* cancel = nullptr);

class Compressor {
 public:
  Compressor();
  ~Compressor();  // stop()
  Compressor(const Compressor&) = delete;
  Compressor& operator=(const Compressor&) = delete;

  // Queues a closed file; files are compressed in the order queued. A file gone by the time its
  // turn comes (deleted by the retention) is skipped.
  void enqueue(std::string path);
  // Abandons the file in progress (it stays plain; the next start compresses it) and the queue;
  // returns once the thread has ended.
  void stop();
  // Blocks until the queue is empty and nothing is in progress (tests, measurements).
  void wait_idle();

  std::uint64_t files_compressed() const noexcept { return compressed_.load(); }

 private:
  void run();

  std::mutex mutex_;
  std::condition_variable wake_;
  std::condition_variable idle_;
  std::deque<std::string> queue_;
  bool busy_ = false;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> compressed_{0};
  std::thread thread_;
};

}  // namespace scp::daemon

#include "daemon/outputs/recording/compressor.hpp"

#include <fcntl.h>
#include <spdlog/spdlog.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <vector>

namespace scp::daemon {

namespace {

constexpr std::size_t kChunk = 256 * 1024;

// Closes the descriptors and removes the temporary file on every way out but success.
struct TmpGuard {
  int in = -1;
  int out = -1;
  std::string tmp;
  bool keep = false;
  z_stream* z = nullptr;
  ~TmpGuard() {
    if (z != nullptr) deflateEnd(z);
    if (in >= 0) ::close(in);
    if (out >= 0) ::close(out);
    if (!keep && !tmp.empty()) ::unlink(tmp.c_str());
  }
};

[[noreturn]] void fail(const std::string& what, const std::string& path, int err) {
  throw std::runtime_error(what + " " + path + ": " + std::strerror(err) +
                           (err == ENOSPC ? " (disk full: the plain file is kept)" : ""));
}

bool write_all(int fd, const unsigned char* data, std::size_t size) {
  while (size > 0) {
    const ssize_t n = ::write(fd, data, size);
    if (n < 0) {
      if (errno == EINTR) continue;
      return false;
    }
    data += n;
    size -= static_cast<std::size_t>(n);
  }
  return true;
}

}  // namespace

bool gzip_file(const std::string& path, int level, const std::atomic<bool>* cancel) {
  const std::string gz = path + ".gz";
  TmpGuard guard;
  guard.in = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (guard.in < 0) fail("cannot read", path, errno);
  struct stat st {};
  if (::fstat(guard.in, &st) != 0) fail("cannot stat", path, errno);
  guard.tmp = gz + ".tmp";
  guard.out =
      ::open(guard.tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, st.st_mode & 0777);
  if (guard.out < 0) {
    guard.tmp.clear();  // not ours to remove
    fail("cannot create", gz + ".tmp", errno);
  }

  z_stream z{};
  // windowBits 15 + 16: a gzip wrapper (header and CRC-32), readable by gzip, zcat and zlib.
  if (deflateInit2(&z, level, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK) {
    throw std::runtime_error("zlib could not start compressing " + path);
  }
  guard.z = &z;
  std::vector<unsigned char> in(kChunk);
  std::vector<unsigned char> out(kChunk);
  int flush = Z_NO_FLUSH;
  while (flush != Z_FINISH) {
    if (cancel != nullptr && cancel->load(std::memory_order_relaxed)) return false;
    const ssize_t n = ::read(guard.in, in.data(), in.size());
    if (n < 0) {
      if (errno == EINTR) continue;
      fail("cannot read", path, errno);
    }
    flush = n == 0 ? Z_FINISH : Z_NO_FLUSH;
    z.next_in = in.data();
    z.avail_in = static_cast<uInt>(n);
    do {
      z.next_out = out.data();
      z.avail_out = static_cast<uInt>(out.size());
      if (deflate(&z, flush) == Z_STREAM_ERROR) {
        throw std::runtime_error("zlib failed while compressing " + path);
      }
      const std::size_t have = out.size() - z.avail_out;
      if (!write_all(guard.out, out.data(), have)) fail("cannot write", guard.tmp, errno);
    } while (z.avail_out == 0);
  }
  // The compressed data reach the disk before the name does, and the name before the plain
  // file goes: a crash at any point leaves every row readable.
  if (::fsync(guard.out) != 0) fail("cannot sync", guard.tmp, errno);
  const int out_fd = guard.out;
  guard.out = -1;
  if (::close(out_fd) != 0) fail("cannot write", guard.tmp, errno);
  if (::rename(guard.tmp.c_str(), gz.c_str()) != 0) fail("cannot rename to", gz, errno);
  guard.keep = true;
  const std::string directory = std::filesystem::path(path).parent_path().string();
  const int dir = ::open(directory.empty() ? "." : directory.c_str(), O_RDONLY | O_DIRECTORY);
  if (dir >= 0) {
    ::fsync(dir);
    ::close(dir);
  }
  if (::unlink(path.c_str()) != 0 && errno == ENOENT) {
    // The retention deleted the plain file meanwhile: its compressed copy goes too.
    ::unlink(gz.c_str());
  }
  return true;
}

Compressor::Compressor() : thread_([this] { run(); }) {}

Compressor::~Compressor() {
  stop();
}

void Compressor::enqueue(std::string path) {
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    queue_.push_back(std::move(path));
  }
  wake_.notify_one();
}

void Compressor::stop() {
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    stop_.store(true);
  }
  wake_.notify_one();
  if (thread_.joinable()) thread_.join();
}

void Compressor::wait_idle() {
  std::unique_lock<std::mutex> lock(mutex_);
  idle_.wait(lock, [this] { return (queue_.empty() && !busy_) || stop_.load(); });
}

void Compressor::run() {
  // The lowest CPU priority (nice 19 for this thread only: Linux applies setpriority to a
  // thread id): the recorder and the socket server go first on a machine with few cores.
  ::setpriority(PRIO_PROCESS, static_cast<id_t>(::gettid()), 19);
  for (;;) {
    std::string path;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      busy_ = false;
      idle_.notify_all();
      wake_.wait(lock, [this] { return stop_.load() || !queue_.empty(); });
      if (stop_.load()) break;
      path = std::move(queue_.front());
      queue_.pop_front();
      busy_ = true;
    }
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) continue;  // deleted by the retention
    try {
      const auto plain = std::filesystem::file_size(path, ec);
      if (gzip_file(path, Z_DEFAULT_COMPRESSION, &stop_)) {
        compressed_.fetch_add(1);
        spdlog::debug("recording: compressed {} ({} bytes)", path, plain);
      }
    } catch (const std::exception& e) {
      if (!std::filesystem::exists(path, ec)) continue;  // the retention was quicker
      spdlog::warn("recording: compression failed, {} stays plain: {}", path, e.what());
    }
  }
  const std::lock_guard<std::mutex> lock(mutex_);
  busy_ = false;
  idle_.notify_all();
}

}  // namespace scp::daemon

#include "daemon/outputs/recording/recorder.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <stdexcept>
#include <vector>

#include "common/clock.hpp"
#include "daemon/analysis/refine/best.hpp"

namespace scp::daemon {

namespace {

constexpr const char* kHeader =
    "t,x,xdot,T,V,V_cmd,theta_hat1,theta_hat2,theta_hat3,theta_hat4,theta_hat5,theta_hat6,"
    "sigma1,sigma2,sigma3,sigma4,sigma5,sigma6,eps1,eps2,af1,af2,af_hat1,af_hat2,state,"
    "refined_theta_hat1,refined_theta_hat2,refined_theta_hat3,refined_theta_hat4,"
    "refined_theta_hat5,refined_theta_hat6,refined_sigma1,refined_sigma2,refined_sigma3,"
    "refined_sigma4,refined_sigma5,refined_sigma6,refined_converged,best,"
    "paper_biased_mechanical,paper_biased_thermal,unix_ns,xdot_source,V_since,"
    "refined_verdict_mechanical,refined_verdict_thermal,I\n";

// <directory>/<actuator>-20261123T083000.123Z.csv: names sort in time order.
std::string recording_name(const std::string& directory, const std::string& actuator) {
  const std::int64_t ms = clock::unix_ns() / 1'000'000;
  const std::time_t seconds = static_cast<std::time_t>(ms / 1000);
  std::tm tm{};
  gmtime_r(&seconds, &tm);
  char stamp[40];
  const std::size_t n = std::strftime(stamp, sizeof stamp, "%Y%m%dT%H%M%S", &tm);
  std::snprintf(stamp + n, sizeof stamp - n, ".%03dZ", static_cast<int>(ms % 1000));
  return directory + "/" + actuator + "-" + stamp + ".csv";
}

}  // namespace

Recorder::Recorder(const std::string& path, RecordRing& ring, RefinedRing* refined)
    : path_(path), ring_(ring), refined_ring_(refined) {
  file_ = std::fopen(path.c_str(), "w");
  if (file_ == nullptr) {
    throw std::runtime_error("cannot write the recording " + path + ": " + std::strerror(errno) +
                             " (does the directory exist and is it writable?)");
  }
  // A large buffer: one write(2) per ~1000 rows.
  std::setvbuf(file_, nullptr, _IOFBF, 1 << 20);
  std::fputs(kHeader, file_);
  thread_ = std::thread([this] { run(); });
}

Recorder::Recorder(const config::RecordingSettings& settings, const std::string& actuator,
                   RecordRing& ring)
    : ring_(ring),
      refined_ring_(nullptr),
      rotating_(true),
      settings_(settings),
      actuator_(actuator) {
  open_file(recording_name(settings_.directory, actuator_));
  if (file_ == nullptr) {
    throw std::runtime_error("cannot write a recording in " + settings_.directory + ": " +
                             std::strerror(errno) +
                             " (does recording.directory exist, and may the daemon write there? "
                             "Under systemd: ReadWritePaths=)");
  }
  if (settings_.compress == config::Compression::gzip) compressor_ = std::make_unique<Compressor>();
}

void Recorder::start(std::uint64_t dropped_marked) {
  dropped_marked_ = dropped_marked;
  compress_leftovers();
  apply_retention();
  thread_ = std::thread([this] { run(); });
}

void Recorder::open_file(const std::string& path) {
  path_ = path;
  file_ = std::fopen(path.c_str(), "w");
  bytes_in_file_ = 0;
  file_opened_ = std::chrono::steady_clock::now();
  error_logged_ = false;
  if (file_ == nullptr) return;
  std::setvbuf(file_, nullptr, _IOFBF, 1 << 20);
  std::fputs(kHeader, file_);
  // The header goes to disk at once: a full disk shows here, before rows are taken from the ring
  // only to be lost in the buffer.
  if (std::fflush(file_) != 0) {
    const int err = errno;
    std::fclose(file_);
    file_ = nullptr;
    std::remove(path.c_str());
    errno = err;
    return;
  }
  bytes_in_file_ = std::strlen(kHeader);
  const std::lock_guard<std::mutex> lock(file_name_mutex_);
  file_name_ = path;
}

std::string Recorder::current_file() const {
  const std::lock_guard<std::mutex> lock(file_name_mutex_);
  return file_name_;
}

void Recorder::rotate() {
  if (file_ != nullptr) {
    const bool failed = std::fclose(file_) != 0;
    file_ = nullptr;
    if (failed) spdlog::warn("recording: closing {} failed: {}", path_, std::strerror(errno));
  }
  // The closed file (also one closed after a write error; a name that could not be opened is
  // not there and is skipped).
  std::error_code ec;
  if (compressor_ && !path_.empty() && std::filesystem::exists(path_, ec))
    compressor_->enqueue(path_);
  std::string name = recording_name(settings_.directory, actuator_);
  // Two rotations within a millisecond (a tiny rotate_size_mib) must not reuse a name.
  for (int i = 0; i < 10 && name <= path_; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
    name = recording_name(settings_.directory, actuator_);
  }
  open_file(name);
  if (file_ == nullptr) {
    if (!open_error_logged_)
      spdlog::warn(
          "recording: cannot open a new file in {}: {}; retrying every second, "
          "meanwhile the loop drops rows (STATUS recording.dropped_rows)",
          settings_.directory, std::strerror(errno));
    open_error_logged_ = true;
    return;
  }
  open_error_logged_ = false;
  apply_retention();
}

namespace {

bool ends_with(const std::string& s, const std::string& tail) {
  return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

// This actuator's recordings in `directory` as their plain names (…/name.csv), sorted, each once:
// name.csv and name.csv.gz are one recording (both exist while it is being compressed).
std::vector<std::string> recordings_of(const std::string& directory, const std::string& actuator) {
  std::vector<std::string> out;
  std::error_code ec;
  const std::string prefix = actuator + "-";
  for (const auto& entry : std::filesystem::directory_iterator(directory, ec)) {
    std::string path = entry.path().string();
    if (entry.path().filename().string().rfind(prefix, 0) != 0) continue;
    if (ends_with(path, ".csv.gz")) path.resize(path.size() - 3);
    if (ends_with(path, ".csv")) out.push_back(std::move(path));
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

}  // namespace

// Deletes this actuator's oldest recordings beyond recording.keep_files (names sort in time); a
// compressed recording counts as one, like the plain file it replaced.
void Recorder::apply_retention() {
  if (settings_.keep_files == 0) return;
  const std::vector<std::string> mine = recordings_of(settings_.directory, actuator_);
  const std::size_t keep = settings_.keep_files;
  std::error_code ec;
  for (std::size_t i = 0; i + keep < mine.size(); ++i) {
    std::filesystem::remove(mine[i], ec);
    std::filesystem::remove(mine[i] + ".gz", ec);
  }
}

void Recorder::compress_leftovers() {
  if (!compressor_) return;
  std::error_code ec;
  const std::string prefix = actuator_ + "-";
  for (const auto& entry : std::filesystem::directory_iterator(settings_.directory, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind(prefix, 0) == 0 && ends_with(name, ".csv.gz.tmp")) {
      std::error_code ignored;
      std::filesystem::remove(entry.path(), ignored);
    }
  }
  for (const auto& path : recordings_of(settings_.directory, actuator_)) {
    if (path != path_ && std::filesystem::exists(path, ec)) compressor_->enqueue(path);
  }
}

Recorder::~Recorder() {
  try {
    finish();
  } catch (...) {
    // finish() was not called by the owner; the error has nowhere to go in a destructor.
  }
}

void Recorder::run() {
  RecordRow row;
  for (;;) {
    // Service mode after a write error: rows stay in the ring (the loop counts what it cannot
    // push, in STATUS) while a new file is tried every second.
    if (rotating_ && file_ == nullptr) {
      if (stop_.load(std::memory_order_acquire)) break;
      std::this_thread::sleep_for(std::chrono::seconds(1));
      rotate();
      if (file_ != nullptr) spdlog::info("recording: writing {} again", path_);
      continue;
    }
    bool any = false;
    while (ring_.try_pop(row)) {
      write_row(row);
      any = true;
    }
    if (!any) {
      if (stop_.load(std::memory_order_acquire) && ring_.size_approx() == 0) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
  }
}

void Recorder::advance_refined(double t) {
  if (refined_ring_ == nullptr) return;
  for (;;) {
    if (!has_pending_) has_pending_ = refined_ring_->try_pop(pending_);
    if (!has_pending_ || pending_.fitted_at_t > t) return;
    refined_ = pending_;
    has_pending_ = false;
  }
}

void Recorder::write_row(const RecordRow& r) {
  advance_refined(r.t);
  // std::to_chars writes the shortest text that reads back as the same double: a replay of this
  // file reproduces the run bit for bit, at a fraction of printf's cost.
  char line[2048];
  char* out = line;
  char* const end = line + sizeof line;
  // Rows missing before this one: a comment line (skipped by --replay) says where and how many,
  // because a replay reproduces the live estimate only up to there.
  const std::uint64_t failed = rows_failed_.load(std::memory_order_relaxed);
  const std::uint64_t dropped_marked_before = dropped_marked_;
  if (r.dropped_before > dropped_marked_ || failed > failed_marked_) {
    out += std::snprintf(out, 256,
                         "# %llu rows missing before this row (%llu dropped by the loop: "
                         "recording ring full; %llu lost to write errors); a replay differs "
                         "from the live run from here\n",
                         static_cast<unsigned long long>(r.dropped_before - dropped_marked_ +
                                                         failed - failed_marked_),
                         static_cast<unsigned long long>(r.dropped_before - dropped_marked_),
                         static_cast<unsigned long long>(failed - failed_marked_));
    dropped_marked_ = r.dropped_before;
    failed_marked_ = failed;
  }
  auto put = [&](double value) {
    out = std::to_chars(out, end, value).ptr;
    *out++ = ',';
  };
  put(r.t);
  put(r.x);
  put(r.xdot);
  put(r.temperature);
  put(r.voltage);
  put(r.voltage_command);
  for (const double v : r.theta_hat) put(v);
  for (const double v : r.sigma) put(v);
  for (const double v : r.eps) put(v);
  for (const double v : r.af) put(v);
  for (const double v : r.af_hat) put(v);
  const char* state = to_string(static_cast<RunState>(r.state));
  const std::size_t state_length = std::strlen(state);
  std::memcpy(out, state, state_length);
  out += state_length;
  *out++ = ',';
  // The refinement's latest fit: empty fields before the first.
  auto put_text = [&](const char* text) {
    const std::size_t n = std::strlen(text);
    std::memcpy(out, text, n);
    out += n;
    *out++ = ',';
  };
  const bool fitted = refined_.valid;
  for (const double v : refined_.theta_hat) fitted ? put(v) : put_text("");
  for (const double v : refined_.sigma) fitted ? put(v) : put_text("");
  put_text(fitted ? (refined_.converged ? "1" : "0") : "");
  put_text(refine::best_name(refine::best_of(&refined_, r.t)));
  put_text(refined_.paper_biased[0] ? "1" : "0");
  put_text(refined_.paper_biased[1] ? "1" : "0");
  out = std::to_chars(out, end, r.unix_ns).ptr;
  *out++ = ',';
  put_text(r.xdot_measured ? "measured" : "estimated");
  std::isfinite(r.voltage_since) ? put(r.voltage_since) : put_text("");
  // The latest fit's validation verdict per block (issue 28): empty before the first.
  put_text(refined_.validated ? scp::refine::verdict_name(refined_.validation.mechanical.verdict)
                              : "");
  put_text(refined_.validated ? scp::refine::verdict_name(refined_.validation.thermal.verdict)
                              : "");
  // The heater's current, empty when the device does not measure it (a replay reads it back).
  std::isfinite(r.current) ? put(r.current) : put_text("");
  out[-1] = '\n';
  const auto size = static_cast<std::size_t>(out - line);
  if (rotating_) {
    const bool too_big =
        settings_.rotate_size_mib > 0.0 &&
        static_cast<double>(bytes_in_file_ + size) > settings_.rotate_size_mib * 1024.0 * 1024.0;
    const bool too_old = settings_.rotate_interval_s > 0.0 &&
                         std::chrono::steady_clock::now() - file_opened_ >
                             std::chrono::duration<double>(settings_.rotate_interval_s);
    if (too_big || too_old) rotate();
    if (file_ == nullptr || std::fwrite(line, 1, size, file_) != size) {
      // The rows in the stdio buffer are lost with this one; the next rows wait in the ring.
      rows_failed_.fetch_add(1, std::memory_order_relaxed);
      dropped_marked_ = dropped_marked_before;  // the mark went with the row: mark again
      if (!error_logged_) {
        spdlog::warn(
            "recording: cannot write {}: {}; retrying with a new file every second, "
            "meanwhile the loop drops rows (STATUS recording.dropped_rows)",
            path_, std::strerror(errno ? errno : EIO));
        error_logged_ = true;
      }
      if (file_ != nullptr) std::fclose(file_);
      file_ = nullptr;
      return;
    }
    bytes_in_file_ += size;
    rows_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  if (std::fwrite(line, 1, size, file_) != size && write_errno_.load() == 0) {
    write_errno_.store(errno ? errno : EIO);
  }
  rows_.fetch_add(1, std::memory_order_relaxed);
}

void Recorder::finish() {
  stop_.store(true, std::memory_order_release);
  if (thread_.joinable()) thread_.join();
  // A file being compressed stays plain (compressed at the next start): stopping does not wait.
  if (compressor_) compressor_->stop();
  if (file_ == nullptr) return;
  int error = write_errno_.load();
  if (std::fflush(file_) != 0 && error == 0) error = errno;
  if (std::fclose(file_) != 0 && error == 0) error = errno;
  file_ = nullptr;
  if (error != 0) {
    throw std::runtime_error("the recording " + path_ + " is incomplete: " + std::strerror(error) +
                             " (disk full?)");
  }
}

}  // namespace scp::daemon

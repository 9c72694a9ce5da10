#include "daemon/service/state/checkpoint.hpp"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <stdexcept>

namespace scp::daemon::state {
namespace {

using nlohmann::json;

// A checkpoint is about 1 kB; anything much larger is not ours and is not read into memory.
constexpr std::size_t kMaxFileBytes = 1 << 20;

std::string errno_text(int err) {
  return std::string(std::strerror(err)) + " (errno " + std::to_string(err) + ")";
}

std::string hex64(std::uint64_t v) {
  char buf[17];
  std::snprintf(buf, sizeof(buf), "%016llx", static_cast<unsigned long long>(v));
  return buf;
}

// Canonical payload: compact dump, keys sorted (nlohmann's object is a std::map), doubles printed
// shortest-round-trip, so load → dump reproduces the bytes that were hashed at save time.
std::string checksum_of(const json& payload) {
  return "fnv1a64:" + hex64(fnv1a64(payload.dump(-1, ' ', false, json::error_handler_t::replace)));
}

template <std::size_t N>
void require_finite(const std::array<double, N>& values, const char* field) {
  for (double v : values) {
    if (!std::isfinite(v)) {
      throw std::runtime_error(std::string("refusing to save a checkpoint: field '") + field +
                               "' holds a non-finite value (the estimate has diverged)");
    }
  }
}

// Owns a file descriptor; closes it on every path.
class Fd {
 public:
  explicit Fd(int fd) : fd_(fd) {}
  ~Fd() {
    if (fd_ >= 0) ::close(fd_);
  }
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  int get() const { return fd_; }
  // Closes explicitly so that a deferred write error (NFS, quota) reported by close() is seen.
  int close_checked() {
    const int rc = ::close(fd_);
    fd_ = -1;
    return rc;
  }

 private:
  int fd_;
};

std::string directory_of(const std::string& path) {
  const auto slash = path.find_last_of('/');
  if (slash == std::string::npos) return ".";
  if (slash == 0) return "/";
  return path.substr(0, slash);
}

// What a state file is, in messages: "checkpoint" or "baseline", and the key that names where it
// lies ("state.path").
struct FileRole {
  std::string_view what;
  std::string_view key;
};
constexpr FileRole kCheckpoint{"checkpoint", "state.path"};

[[noreturn]] void fail_write(const std::string& path, const FileRole& role, const std::string& step,
                             int err) {
  throw std::runtime_error(
      "cannot save " + std::string(role.what) + " " + path + ": " + step + ": " + errno_text(err) +
      (err == ENOSPC ? " — free space on that file system" : "") +
      (err == EACCES || err == EROFS ? " — check that " + std::string(role.key) +
                                           " lies in a writable directory (the unit's "
                                           "StateDirectory=)"
                                     : std::string()));
}

void write_atomically(const std::string& path, const std::string& data, const FileRole& role) {
  const std::string tmp = path + ".tmp." + std::to_string(getpid());
  // Any failure after the temporary exists removes it before reporting.
  auto fail = [&](const std::string& step, int err) {
    ::unlink(tmp.c_str());
    fail_write(path, role, step, err);
  };
  {
    // O_EXCL | O_NOFOLLOW: never write through a name someone else prepared (a symlink planted
    // in the state directory would make a root daemon overwrite the file it points to).
    constexpr int kFlags = O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC;
    int raw = ::open(tmp.c_str(), kFlags, 0640);
    if (raw < 0 && errno == EEXIST) {
      // Ours from an earlier process with the same pid (a container restarts at the same pid)
      // may go; anything else is refused.
      struct stat st {};
      if (::lstat(tmp.c_str(), &st) == 0 && S_ISREG(st.st_mode) && st.st_uid == ::geteuid() &&
          st.st_nlink == 1) {
        ::unlink(tmp.c_str());
        raw = ::open(tmp.c_str(), kFlags, 0640);
      } else {
        throw std::runtime_error("refusing to save " + std::string(role.what) + " " + path + ": " +
                                 tmp +
                                 " already exists and is not a file of ours (a symlink, FIFO or "
                                 "another user's file planted there?); remove it and check who "
                                 "can write to the state directory");
      }
    }
    Fd fd(raw);
    if (fd.get() < 0) fail_write(path, role, "cannot create " + tmp, errno);
    std::size_t done = 0;
    while (done < data.size()) {
      const ssize_t n = ::write(fd.get(), data.data() + done, data.size() - done);
      if (n < 0) {
        if (errno == EINTR) continue;
        fail("write to " + tmp + " failed", errno);
      }
      done += static_cast<std::size_t>(n);
    }
    // fsync before rename: otherwise a power cut can leave the new name pointing at empty data.
    if (::fsync(fd.get()) != 0) fail("fsync of " + tmp + " failed", errno);
    if (fd.close_checked() != 0) fail("close of " + tmp + " failed", errno);
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) fail("rename of " + tmp + " failed", errno);
  // fsync the directory so the rename itself survives a power cut.
  const std::string dir = directory_of(path);
  Fd dfd(::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
  if (dfd.get() < 0) fail_write(path, role, "cannot open directory " + dir + " to fsync it", errno);
  if (::fsync(dfd.get()) != 0)
    fail_write(path, role, "fsync of directory " + dir + " failed", errno);
}

// A crash between creating path.tmp.<pid> and the rename leaves that file behind; remove those of
// processes that no longer exist (best effort: a failure here must not fail the save).
void remove_stale_temporaries(const std::string& path) {
  const std::string dir = directory_of(path);
  const auto slash = path.find_last_of('/');
  const std::string prefix = (slash == std::string::npos ? path : path.substr(slash + 1)) + ".tmp.";
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind(prefix, 0) != 0) continue;
    const std::string digits = name.substr(prefix.size());
    if (digits.empty() || digits.size() > 9 ||
        digits.find_first_not_of("0123456789") != std::string::npos) {
      continue;
    }
    const auto pid = static_cast<pid_t>(std::stol(digits));
    if (pid != getpid() && ::kill(pid, 0) != 0 && errno == ESRCH) {
      std::filesystem::remove(entry.path(), ec);
    }
  }
}

// Reads the whole file; on failure returns false with a reason.
bool read_file(const std::string& path, std::string& out, std::string& reason,
               const FileRole& role) {
  const std::string what(role.what);
  // O_NONBLOCK: opening a FIFO planted under the file's name must not hang start-up;
  // O_NOFOLLOW: a symlink is not ours to follow. Only a regular file is then read.
  Fd fd(::open(path.c_str(), O_RDONLY | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC));
  if (fd.get() < 0) {
    const int err = errno;
    reason = err == ENOENT  ? "no " + what + " at " + path
             : err == ELOOP ? "refusing " + what + " " + path + ": it is a symbolic link"
                            : "cannot open " + path + ": " + errno_text(err);
    return false;
  }
  struct stat st {};
  if (::fstat(fd.get(), &st) != 0 || !S_ISREG(st.st_mode)) {
    reason = "refusing " + what + " " + path + ": not a regular file (a FIFO, device or directory)";
    return false;
  }
  if (st.st_uid != ::geteuid() && st.st_uid != 0) {
    reason = "refusing " + what + " " + path + ": owned by uid " + std::to_string(st.st_uid) +
             ", not by this daemon's user or root";
    return false;
  }
  char buf[4096];
  for (;;) {
    const ssize_t n = ::read(fd.get(), buf, sizeof(buf));
    if (n < 0) {
      if (errno == EINTR) continue;
      reason = "cannot read " + path + ": " + errno_text(errno);
      return false;
    }
    if (n == 0) break;
    out.append(buf, static_cast<std::size_t>(n));
    if (out.size() > kMaxFileBytes) {
      reason = path + " is larger than " + std::to_string(kMaxFileBytes) + " bytes; not a " + what;
      return false;
    }
  }
  return true;
}

// Reads a numeric array of exactly N finite numbers; NaN/Inf are stored as null by JSON writers.
template <std::size_t N>
bool get_array(const json& j, const char* key, std::array<double, N>& out, std::string& reason) {
  const auto it = j.find(key);
  if (it == j.end() || !it->is_array() || it->size() != N) {
    reason = std::string("field '") + key + "' is missing or is not an array of " +
             std::to_string(N) + " numbers";
    return false;
  }
  for (std::size_t i = 0; i < N; ++i) {
    const json& v = (*it)[i];
    if (!v.is_number() || !std::isfinite(v.get<double>())) {
      reason = std::string("field '") + key + "[" + std::to_string(i) + "]' is not a finite number";
      return false;
    }
    out[i] = v.get<double>();
  }
  return true;
}

template <int N>
bool symmetric_positive_definite(const double* row_major, const char* key, std::string& reason) {
  const Eigen::Map<const Eigen::Matrix<double, N, N, Eigen::RowMajor>> m(row_major);
  const double scale = m.cwiseAbs().maxCoeff();
  if (!((m - m.transpose()).cwiseAbs().maxCoeff() <= 1e-9 * scale)) {
    reason = std::string("field '") + key + "' is not a symmetric matrix";
    return false;
  }
  const Eigen::Matrix<double, N, N> sym = 0.5 * (m + m.transpose());
  Eigen::LLT<Eigen::Matrix<double, N, N>> llt(sym);
  if (scale == 0.0 || llt.info() != Eigen::Success ||
      !(llt.matrixL().toDenseMatrix().diagonal().minCoeff() > 0.0)) {
    reason = std::string("field '") + key + "' is not a positive definite matrix";
    return false;
  }
  return true;
}

std::optional<Checkpoint> parse(const std::string& text, std::string& reason) {
  const json j = json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded() || !j.is_object()) {
    reason = "it is truncated or not valid JSON";
    return std::nullopt;
  }
  const auto format = j.find("format");
  if (format == j.end() || !format->is_string() ||
      format->get<std::string>() != kCheckpointFormat) {
    reason = "it is not an scp-estimator state file (\"format\" is not \"scp-estimator-state\")";
    return std::nullopt;
  }
  const auto version = j.find("version");
  if (version == j.end() || !version->is_number_integer() ||
      version->get<std::int64_t>() != kCheckpointVersion) {
    reason = "it has version " + (version == j.end() ? std::string("(none)") : version->dump()) +
             ", this daemon reads version " + std::to_string(kCheckpointVersion);
    return std::nullopt;
  }
  const auto checksum = j.find("checksum");
  if (checksum == j.end() || !checksum->is_string()) {
    reason = "it has no checksum";
    return std::nullopt;
  }
  json payload = j;
  payload.erase("checksum");
  if (checksum->get<std::string>() != checksum_of(payload)) {
    reason = "its checksum does not match its contents (corrupted or edited)";
    return std::nullopt;
  }

  Checkpoint c;
  if (!get_array(j, "theta_hat", c.theta_hat, reason) ||
      !get_array(j, "info_mech", c.info_mech, reason) ||
      !get_array(j, "info_thermal", c.info_thermal, reason) ||
      !get_array(j, "eps2_mean", c.eps2_mean, reason)) {
    return std::nullopt;
  }
  const auto t = j.find("t");
  if (t == j.end() || !t->is_number() || !std::isfinite(t->get<double>())) {
    reason = "field 't' is missing or not a finite number";
    return std::nullopt;
  }
  c.t = t->get<double>();
  const auto driver = j.find("driver");
  const auto wall = j.find("wall_time_unix");
  if (driver == j.end() || !driver->is_string()) {
    reason = "field 'driver' is missing or not a string";
    return std::nullopt;
  }
  if (wall == j.end() || !wall->is_number_integer()) {
    reason = "field 'wall_time_unix' is missing or not an integer";
    return std::nullopt;
  }
  c.driver = driver->get<std::string>();
  c.wall_time_unix = wall->get<std::int64_t>();
  for (const auto& [key, field] :
       {std::pair{"actuator", &c.actuator}, std::pair{"endpoint", &c.endpoint}}) {
    const auto it = j.find(key);
    if (it == j.end()) continue;
    if (!it->is_string()) {
      reason = std::string("field '") + key + "' is not a string";
      return std::nullopt;
    }
    *field = it->get<std::string>();
  }
  for (double e : c.eps2_mean) {
    if (e < 0.0) {
      reason = "field 'eps2_mean' holds a negative mean square";
      return std::nullopt;
    }
  }
  if (!symmetric_positive_definite<4>(c.info_mech.data(), "info_mech", reason) ||
      !symmetric_positive_definite<2>(c.info_thermal.data(), "info_thermal", reason)) {
    return std::nullopt;
  }
  return c;
}

}  // namespace

void write_state_file(const std::string& path, const std::string& data, std::string_view what,
                      std::string_view key) {
  write_atomically(path, data, FileRole{what, key});
  remove_stale_temporaries(path);
}

bool read_state_file(const std::string& path, std::string& out, std::string& reason,
                     std::string_view what, std::string_view key) {
  return read_file(path, out, reason, FileRole{what, key});
}

std::uint64_t fnv1a64(std::string_view data) noexcept {
  std::uint64_t h = 0xcbf29ce484222325ULL;
  for (unsigned char c : data) {
    h ^= c;
    h *= 0x100000001b3ULL;
  }
  return h;
}

void save_checkpoint(const std::string& path, const Checkpoint& c) {
  require_finite(c.theta_hat, "theta_hat");
  require_finite(c.info_mech, "info_mech");
  require_finite(c.info_thermal, "info_thermal");
  require_finite(c.eps2_mean, "eps2_mean");
  require_finite(std::array<double, 1>{c.t}, "t");

  json j = {
      {"format", kCheckpointFormat},
      {"version", kCheckpointVersion},
      {"theta_hat", c.theta_hat},
      {"info_mech", c.info_mech},
      {"info_thermal", c.info_thermal},
      {"eps2_mean", c.eps2_mean},
      {"t", c.t},
      {"driver", c.driver},
      {"wall_time_unix", c.wall_time_unix},
      {"actuator", c.actuator},
      {"endpoint", c.endpoint},
  };
  j["checksum"] = checksum_of(j);
  // Invalid UTF-8 in the driver name is replaced rather than thrown on.
  write_atomically(path, j.dump(2, ' ', false, json::error_handler_t::replace) + "\n", kCheckpoint);
  remove_stale_temporaries(path);
}

std::optional<Checkpoint> load_checkpoint(const std::string& path, std::string& warning) {
  warning.clear();
  std::string text;
  std::string reason;
  if (!read_file(path, text, reason, kCheckpoint)) {
    warning = reason + "; starting cold";
    return std::nullopt;
  }
  auto c = parse(text, reason);
  if (!c) warning = "ignoring checkpoint " + path + ": " + reason + "; starting cold";
  return c;
}

}  // namespace scp::daemon::state

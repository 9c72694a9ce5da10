#include "daemon/service/state/state_directory.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>

namespace scp::daemon::state {

void check_state_directory(const std::string& directory) {
  struct stat st {};
  if (::lstat(directory.c_str(), &st) != 0) {
    const int err = errno;
    throw std::runtime_error("state.directory " + directory + ": " + std::strerror(err) +
                             (err == ENOENT
                                  ? "; create it (mkdir -m 0750), or let systemd do it with "
                                    "StateDirectory=scp-estimator in the unit"
                                  : "; check state.directory"));
  }
  if (!S_ISDIR(st.st_mode)) {
    throw std::runtime_error("state.directory " + directory +
                             " is not a directory (a symlink or a file); point state.directory "
                             "at a real directory");
  }
  if (st.st_uid != ::geteuid() && st.st_uid != 0) {
    throw std::runtime_error("state.directory " + directory + " belongs to uid " +
                             std::to_string(st.st_uid) +
                             ", neither this daemon's user nor root; chown it to the daemon's "
                             "user");
  }
  if ((st.st_mode & (S_IWGRP | S_IWOTH)) != 0) {
    throw std::runtime_error(
        "state.directory " + directory +
        " is writable by its group or by everyone: another user could plant a symlink or FIFO "
        "where the checkpoint goes; chmod go-w " +
        directory);
  }
}

namespace {

// What the holder of the lock wrote into it: "pid 4242, actuator bench-a, socket ...".
std::string lock_holder(int fd) {
  char text[512];
  const ssize_t n = ::pread(fd, text, sizeof text - 1, 0);
  if (n <= 0) return {};
  std::string out(text, static_cast<std::size_t>(n));
  while (!out.empty() && (out.back() == '\n' || out.back() == '\0')) out.pop_back();
  return out;
}

}  // namespace

StateLock::StateLock(const std::string& directory, const std::string& holder) {
  const std::string path = directory + "/scp-estimatord.lock";
  fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_NOFOLLOW | O_CLOEXEC, 0600);
  if (fd_ < 0) {
    throw std::runtime_error("cannot open the lock file " + path + ": " + std::strerror(errno) +
                             "; check that state.directory is writable by the daemon");
  }
  if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    const std::string other = err == EWOULDBLOCK ? lock_holder(fd_) : std::string();
    ::close(fd_);
    fd_ = -1;
    if (err == EWOULDBLOCK) {
      throw std::runtime_error("another scp-estimatord already runs on state directory " +
                               directory + (other.empty() ? "" : " (" + other + ")") +
                               "; stop it first (systemctl stop scp-estimatord) or give this one "
                               "its own state.directory and socket.path (several actuators: "
                               "scp-estimatord@NAME.service)");
    }
    throw std::runtime_error("cannot lock " + path + ": " + std::strerror(err));
  }
  // Who holds it, for the message a second daemon gets. Best effort: the lock is what counts.
  const std::string text =
      "pid " + std::to_string(::getpid()) + (holder.empty() ? "" : ", " + holder) + "\n";
  if (::ftruncate(fd_, 0) == 0) {
    [[maybe_unused]] const ssize_t n = ::pwrite(fd_, text.data(), text.size(), 0);
  }
}

StateLock::~StateLock() {
  if (fd_ >= 0) ::close(fd_);  // releases the lock
}

}  // namespace scp::daemon::state

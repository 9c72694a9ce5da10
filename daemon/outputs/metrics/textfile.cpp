#include "daemon/outputs/metrics/textfile.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>

namespace scp::daemon::metrics {

void write_textfile(const std::string& directory, const std::string& file_name,
                    const std::string& text) {
  const std::string target = directory + "/" + file_name;
  // node_exporter reads only *.prom: a temporary name without that suffix is never collected.
  const std::string temporary = target + ".tmp." + std::to_string(::getpid());
  const int fd =
      ::open(temporary.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_NOFOLLOW | O_CLOEXEC, 0644);
  if (fd < 0) {
    throw std::runtime_error("cannot write metrics to " + temporary + ": " + std::strerror(errno) +
                             "; check metrics.textfile_directory and that the daemon may write "
                             "there (ReadWritePaths= under systemd)");
  }
  std::size_t written = 0;
  while (written < text.size()) {
    const ssize_t n = ::write(fd, text.data() + written, text.size() - written);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int err = n < 0 ? errno : ENOSPC;
      ::close(fd);
      ::unlink(temporary.c_str());
      throw std::runtime_error("cannot write metrics to " + temporary + ": " + std::strerror(err));
    }
    written += static_cast<std::size_t>(n);
  }
  if (::close(fd) != 0 || ::rename(temporary.c_str(), target.c_str()) != 0) {
    const int err = errno;
    ::unlink(temporary.c_str());
    throw std::runtime_error("cannot replace " + target + ": " + std::strerror(err));
  }
}

}  // namespace scp::daemon::metrics

#include "daemon/core/rt/sd_notify.hpp"

#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <utility>

namespace scp::rt {
namespace {

constexpr char kReady[] = "READY=1";
constexpr char kStopping[] = "STOPPING=1";
constexpr char kWatchdog[] = "WATCHDOG=1";
constexpr char kWatchdogTrigger[] = "WATCHDOG=trigger";

// Strict unsigned decimal parse: the whole string, no sign, no overflow.
bool parse_unsigned(const char* text, unsigned long long& out) {
  if (text == nullptr || *text < '0' || *text > '9') return false;
  errno = 0;
  char* end = nullptr;
  out = std::strtoull(text, &end, 10);
  return errno == 0 && end != nullptr && *end == '\0';
}

}  // namespace

ServiceNotifier ServiceNotifier::from_environment() {
  return from_values(std::getenv("NOTIFY_SOCKET"), std::getenv("WATCHDOG_USEC"),
                     std::getenv("WATCHDOG_PID"), static_cast<long>(getpid()));
}

ServiceNotifier ServiceNotifier::from_values(const char* notify_socket, const char* watchdog_usec,
                                             const char* watchdog_pid, long pid) {
  ServiceNotifier n;
  if (notify_socket == nullptr || *notify_socket == '\0') return n;

  const std::string_view path(notify_socket);
  if (path.front() != '/' && path.front() != '@') {
    n.problem_ = "NOTIFY_SOCKET=" + std::string(path) +
                 " is neither a path nor an abstract socket (@name); systemd notification is off";
    return n;
  }
  if (path.size() >= sizeof(n.address_.sun_path)) {
    n.problem_ = "NOTIFY_SOCKET is longer than " + std::to_string(sizeof(n.address_.sun_path) - 1) +
                 " characters; systemd notification is off";
    return n;
  }
  n.address_.sun_family = AF_UNIX;
  std::memcpy(n.address_.sun_path, path.data(), path.size());
  // An abstract address starts with NUL and its length counts exactly its bytes (unix(7)).
  if (path.front() == '@') n.address_.sun_path[0] = '\0';
  n.address_size_ = static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + path.size() +
                                           (path.front() == '/' ? 1 : 0));

  n.fd_ = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
  if (n.fd_ < 0) {
    n.problem_ = std::string("cannot create the systemd notification socket: ") +
                 std::strerror(errno) + "; systemd notification is off";
    return n;
  }

  if (watchdog_usec != nullptr) {
    unsigned long long usec = 0;
    unsigned long long owner = 0;
    if (!parse_unsigned(watchdog_usec, usec) || usec == 0) {
      n.problem_ = "WATCHDOG_USEC=" + std::string(watchdog_usec) +
                   " is not a positive integer; the watchdog is not petted";
    } else if (watchdog_pid != nullptr && (!parse_unsigned(watchdog_pid, owner) ||
                                           owner != static_cast<unsigned long long>(pid))) {
      // The watchdog belongs to another process (e.g. we are a child of the main process).
      n.problem_ = "WATCHDOG_PID=" + std::string(watchdog_pid) + " is not this process (" +
                   std::to_string(pid) + "); the watchdog is not petted";
    } else {
      n.watchdog_interval_ = std::chrono::microseconds(static_cast<std::int64_t>(usec));
    }
  }
  return n;
}

ServiceNotifier::~ServiceNotifier() {
  close_fd();
}

ServiceNotifier::ServiceNotifier(ServiceNotifier&& other) noexcept
    : fd_(std::exchange(other.fd_, -1)),
      address_(other.address_),
      address_size_(other.address_size_),
      watchdog_interval_(other.watchdog_interval_),
      problem_(std::move(other.problem_)) {}

ServiceNotifier& ServiceNotifier::operator=(ServiceNotifier&& other) noexcept {
  if (this != &other) {
    close_fd();
    fd_ = std::exchange(other.fd_, -1);
    address_ = other.address_;
    address_size_ = other.address_size_;
    watchdog_interval_ = other.watchdog_interval_;
    problem_ = std::move(other.problem_);
  }
  return *this;
}

void ServiceNotifier::close_fd() noexcept {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

bool ServiceNotifier::send(const char* data, std::size_t size) noexcept {
  if (fd_ < 0) return false;
  // MSG_DONTWAIT: a stalled systemd must never block the loop; MSG_NOSIGNAL: no SIGPIPE.
  const ssize_t sent = sendto(fd_, data, size, MSG_DONTWAIT | MSG_NOSIGNAL,
                              reinterpret_cast<const sockaddr*>(&address_), address_size_);
  return sent == static_cast<ssize_t>(size);
}

bool ServiceNotifier::ready() noexcept {
  return send(kReady, sizeof(kReady) - 1);
}
bool ServiceNotifier::stopping() noexcept {
  return send(kStopping, sizeof(kStopping) - 1);
}
bool ServiceNotifier::watchdog() noexcept {
  if (watchdog_interval_.count() == 0) return false;
  return send(kWatchdog, sizeof(kWatchdog) - 1);
}
bool ServiceNotifier::watchdog_trigger() noexcept {
  return send(kWatchdogTrigger, sizeof(kWatchdogTrigger) - 1);
}

bool ServiceNotifier::status(std::string_view text) {
  if (fd_ < 0) return false;
  std::string message = "STATUS=";
  message.append(text);
  for (char& c : message) {
    if (c == '\n' || c == '\0') c = ' ';
  }
  return send(message.data(), message.size());
}

WatchdogPacer::WatchdogPacer(std::chrono::microseconds interval,
                             std::chrono::nanoseconds period) noexcept {
  if (interval.count() <= 0 || period.count() <= 0) return;
  const auto half = std::chrono::duration_cast<std::chrono::nanoseconds>(interval) / 2;
  const std::int64_t cycles = half.count() / period.count();
  cycles_per_ping_ = cycles < 1 ? 1 : static_cast<std::uint64_t>(cycles);
}

bool WatchdogPacer::due(std::uint64_t cycle) noexcept {
  if (cycles_per_ping_ == 0) return false;
  if (first_ || cycle < last_ || cycle - last_ >= cycles_per_ping_) {
    first_ = false;
    last_ = cycle;
    return true;
  }
  return false;
}

}  // namespace scp::rt

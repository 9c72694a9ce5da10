#pragma once
// The systemd notification protocol (sd_notify(3)), implemented without libsystemd: datagrams such
// as "READY=1" sent to the AF_UNIX socket named by $NOTIFY_SOCKET. The socket is opened once at
// start-up, so watchdog() is a single non-blocking sendto() of a constant buffer — callable from
// the real-time loop (no allocation, no lock, no blocking).

#include <sys/socket.h>
#include <sys/un.h>

#include <chrono>
#include <cstdint>
#include <string>
#include <string_view>

namespace scp::rt {

class ServiceNotifier {
 public:
  // Disabled notifier: every call is a no-op (the daemon runs outside systemd).
  ServiceNotifier() = default;
  // Reads NOTIFY_SOCKET ("/path" or "@abstract"), WATCHDOG_USEC and WATCHDOG_PID. Never throws:
  // an unusable setting leaves the notifier disabled and explains why in problem().
  static ServiceNotifier from_environment();
  // Same, from explicit values (tests; nullptr = variable unset). `pid` is this process's pid.
  static ServiceNotifier from_values(const char* notify_socket, const char* watchdog_usec,
                                     const char* watchdog_pid, long pid);

  ~ServiceNotifier();
  ServiceNotifier(ServiceNotifier&& other) noexcept;
  ServiceNotifier& operator=(ServiceNotifier&& other) noexcept;
  ServiceNotifier(const ServiceNotifier&) = delete;
  ServiceNotifier& operator=(const ServiceNotifier&) = delete;

  bool enabled() const noexcept { return fd_ >= 0; }
  // Why the notifier is disabled although NOTIFY_SOCKET was set, or why the watchdog is off
  // although WATCHDOG_USEC was set; empty otherwise. For the start-up log.
  const std::string& problem() const noexcept { return problem_; }

  // Each returns false when the notifier is disabled or the datagram could not be sent.
  bool ready() noexcept;
  bool stopping() noexcept;
  bool watchdog() noexcept;  // real-time safe
  // "STATUS=<text>" (shown by systemctl status); newlines are replaced by spaces. Not real-time.
  bool status(std::string_view text);
  // "WATCHDOG=trigger": asks systemd to act as if the watchdog expired (a fatal internal fault).
  bool watchdog_trigger() noexcept;

  // The service's watchdog interval (0 = no watchdog, or WATCHDOG_PID names another process).
  std::chrono::microseconds watchdog_interval() const noexcept { return watchdog_interval_; }

 private:
  bool send(const char* data, std::size_t size) noexcept;
  void close_fd() noexcept;

  int fd_ = -1;
  sockaddr_un address_{};
  socklen_t address_size_ = 0;
  std::chrono::microseconds watchdog_interval_{0};
  std::string problem_;
};

// Decides, from the loop's cycle index alone, when to pet the watchdog: at most every half
// watchdog interval as systemd recommends (sd_watchdog_enabled(3)). Because the cycle index
// counts skipped periods too (t = k · period), this needs no clock call of its own.
class WatchdogPacer {
 public:
  WatchdogPacer() = default;  // never due
  // interval 0 → never due. A period longer than half the interval → due every cycle.
  WatchdogPacer(std::chrono::microseconds interval, std::chrono::nanoseconds period) noexcept;

  // True on the first call and then whenever at least the pacing interval has passed since the
  // cycle that last returned true. Call once per healthy cycle; skip the call while unhealthy so
  // that systemd restarts a wedged daemon.
  bool due(std::uint64_t cycle) noexcept;
  std::uint64_t cycles_per_ping() const noexcept { return cycles_per_ping_; }

 private:
  std::uint64_t cycles_per_ping_ = 0;  // 0 = disabled
  std::uint64_t last_ = 0;
  bool first_ = true;
};

}  // namespace scp::rt

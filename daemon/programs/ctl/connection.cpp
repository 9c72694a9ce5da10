#include "daemon/programs/ctl/connection.hpp"

#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <system_error>

namespace scp::daemon::ctl {
namespace {

constexpr std::size_t kMaxReply = 4 << 20;  // far above any reply; guards against a runaway peer

std::string errno_text(int err) {
  return std::error_code(err, std::generic_category()).message();
}

timeval to_timeval(double seconds) {
  timeval tv{};
  tv.tv_sec = static_cast<time_t>(seconds);
  tv.tv_usec = static_cast<suseconds_t>((seconds - std::floor(seconds)) * 1e6);
  return tv;
}

}  // namespace

Connection::Connection(std::string path, double timeout_s)
    : path_(std::move(path)), timeout_s_(timeout_s) {
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  if (path_.empty() || path_.size() >= sizeof(addr.sun_path))
    throw CtlError(kExitUnreachable, "socket path '" + path_ + "' is empty or too long");
  path_.copy(addr.sun_path, path_.size());
  fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd_ < 0) throw CtlError(kExitUnreachable, "cannot create a socket: " + errno_text(errno));
  // On Unix sockets a blocking connect waits for backlog room at most SO_SNDTIMEO.
  const timeval tv = to_timeval(timeout_s_);
  ::setsockopt(fd_, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof(tv));
  if (::connect(fd_, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)) != 0) {
    const int err = errno;
    ::close(fd_);
    fd_ = -1;
    std::string message = "cannot connect to " + path_ + ": " + errno_text(err);
    if (err == ENOENT || err == ECONNREFUSED)
      message += " — is scp-estimatord running? (systemctl status scp-estimatord)";
    else if (err == EACCES || err == EPERM)
      message += " — the socket belongs to the daemon's group; add yourself to it or use sudo";
    else if (err == EAGAIN || err == ETIMEDOUT)
      message += " — the daemon is not accepting connections; is it overloaded or stuck?";
    throw CtlError(kExitUnreachable, message);
  }
  version_ = read_object(timeout_s_);
  // A server that refuses the connection (too many clients) says why in an ERROR object.
  if (version_.value("class", "") == "ERROR")
    throw CtlError(kExitUnreachable, "the daemon refused the connection: " +
                                         version_.value("message", std::string()));
  if (version_.value("class", "") != "VERSION")
    throw CtlError(kExitUnreachable, path_ +
                                         " did not greet with a VERSION object; is it "
                                         "really scp-estimatord's socket?");
  if (version_.value("proto_major", 0) != 1)
    throw CtlError(kExitUnreachable, "the daemon speaks protocol " + version_.dump() +
                                         "; this scp-estimatorctl speaks 1.x — use the "
                                         "scp-estimatorctl installed with the daemon");
}

Connection::~Connection() {
  if (fd_ >= 0) ::close(fd_);
}

void Connection::send(const nlohmann::json& request) {
  const std::string text = request.dump() + '\n';
  std::size_t sent = 0;
  while (sent < text.size()) {
    const ssize_t n = ::send(fd_, text.data() + sent, text.size() - sent, MSG_NOSIGNAL);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0)
      throw CtlError(kExitUnreachable,
                     "lost the connection to " + path_ + ": " + errno_text(n < 0 ? errno : EPIPE));
    sent += static_cast<std::size_t>(n);
  }
}

std::string Connection::read_line(double timeout_s) {
  using Clock = std::chrono::steady_clock;
  const auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                           std::chrono::duration<double>(timeout_s));
  for (;;) {
    const std::size_t newline = buffer_.find('\n');
    if (newline != std::string::npos) {
      std::string line = buffer_.substr(0, newline);
      buffer_.erase(0, newline + 1);
      return line;
    }
    if (buffer_.size() > kMaxReply)
      throw CtlError(kExitUnreachable, "the daemon sent an over-long line; giving up");
    const auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
    if (left <= 0)
      throw CtlError(kExitUnreachable, "no answer from " + path_ + " within " +
                                           std::to_string(timeout_s) +
                                           " s; is the daemon stuck? (systemctl status "
                                           "scp-estimatord)");
    pollfd pfd{fd_, POLLIN, 0};
    const int ready = ::poll(&pfd, 1, static_cast<int>(left));
    if (ready < 0 && errno == EINTR) continue;
    if (ready <= 0) continue;
    char chunk[65536];
    const ssize_t n = ::recv(fd_, chunk, sizeof(chunk), 0);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0)
      throw CtlError(kExitUnreachable, "the daemon closed the connection" +
                                           (n < 0 ? ": " + errno_text(errno) : std::string()));
    buffer_.append(chunk, static_cast<std::size_t>(n));
  }
}

nlohmann::json Connection::read_object(double timeout_s) {
  const std::string line = read_line(timeout_s);
  nlohmann::json object = nlohmann::json::parse(line, nullptr, false);
  if (object.is_discarded() || !object.is_object())
    throw CtlError(kExitUnreachable,
                   "the daemon sent something that is not a JSON object: " + line.substr(0, 200));
  return object;
}

nlohmann::json Connection::exchange(const nlohmann::json& request) {
  send(request);
  for (;;) {
    nlohmann::json reply = read_object(timeout_s_);
    const std::string cls = reply.value("class", "");
    if (cls == "ESTIMATE" && request.value("request", "") != "estimate") continue;
    if (cls == "ERROR")
      throw CtlError(kExitRefused, "scp-estimatord: " + reply.value("message", "(no message)"));
    return reply;
  }
}

}  // namespace scp::daemon::ctl

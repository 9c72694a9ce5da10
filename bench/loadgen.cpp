// scp-loadgen: a bounded load on the daemon's socket, for scripts/bench. `clients` threads each ask
// `estimate` as fast as the daemon answers (one request in flight per client, so latency is the
// round trip), `watchers` threads hold a `watch` stream and read it, all for `duration` seconds of
// wall time; then every connection is closed. Prints one JSON object: requests/s and the latency
// percentiles over all clients, and the ESTIMATE lines the watchers received.
//
//   scp-loadgen --socket PATH [--clients 64] [--watchers 8] [--watch-rate 100] [--duration 10]
//               [--echo-server]
//
// --echo-server first starts, in this process, a reference server on PATH: one thread, poll() over
// all connections, a VERSION line on connect and a fixed ESTIMATE-sized line for every request
// line, the least any server can do. The same clients against it measure the Unix socket itself.
//
// Only the local Unix socket is used; every read has a 2 s timeout, so a wedged daemon ends the run
// with errors counted rather than a hang.

#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

struct Options {
  std::string socket;
  int clients = 64;
  int watchers = 8;
  double watch_rate_hz = 100.0;
  double duration_s = 10.0;
  bool echo_server = false;
  // What each client sends, one line (e.g. another request, or the same one spelled differently).
  std::string request = R"({"request":"estimate"})";
};

[[noreturn]] void usage(const char* why) {
  std::fprintf(stderr,
               "scp-loadgen: %s\nusage: scp-loadgen --socket PATH [--clients N (0..1000)] "
               "[--watchers M (0..1000)] [--watch-rate HZ (0.1..1000)] [--duration S (0.1..3600)] "
               "[--echo-server] [--request JSON (default {\"request\":\"estimate\"})]\n",
               why);
  std::exit(2);
}

Options parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    if (arg == "--echo-server") {
      o.echo_server = true;
      continue;
    }
    if (i + 1 >= argc) usage(("missing value after " + std::string(arg)).c_str());
    const char* value = argv[++i];
    char* end = nullptr;
    const double number = std::strtod(value, &end);
    const bool numeric = end != value && *end == '\0' && std::isfinite(number);
    if (arg == "--socket") {
      o.socket = value;
    } else if (arg == "--request" && *value != '\0' && std::strchr(value, '\n') == nullptr) {
      o.request = value;
    } else if (arg == "--clients" && numeric && number >= 0 && number <= 1000) {
      o.clients = static_cast<int>(number);
    } else if (arg == "--watchers" && numeric && number >= 0 && number <= 1000) {
      o.watchers = static_cast<int>(number);
    } else if (arg == "--watch-rate" && numeric && number >= 0.1 && number <= 1000) {
      o.watch_rate_hz = number;
    } else if (arg == "--duration" && numeric && number >= 0.1 && number <= 3600) {
      o.duration_s = number;
    } else {
      usage(("bad option or out-of-range value: " + std::string(arg) + " " + value).c_str());
    }
  }
  if (o.socket.empty()) usage("--socket is required");
  if (o.socket.size() >= sizeof(sockaddr_un::sun_path)) usage("--socket path too long");
  return o;
}

// One connection with a line reader; every wait is bounded.
class Connection {
 public:
  explicit Connection(const std::string& path) {
    fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd_ < 0) return;
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
    if (::connect(fd_, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)) != 0) {
      ::close(fd_);
      fd_ = -1;
    }
  }
  ~Connection() {
    if (fd_ >= 0) ::close(fd_);
  }
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;

  bool ok() const { return fd_ >= 0; }

  bool send(std::string_view text) {
    while (!text.empty()) {
      const ssize_t n = ::send(fd_, text.data(), text.size(), MSG_NOSIGNAL);
      if (n <= 0) return false;
      text.remove_prefix(static_cast<std::size_t>(n));
    }
    return true;
  }

  // Next line (without '\n') into `line`; false on timeout, EOF or error.
  bool read_line(std::string& line, int timeout_ms = 2000) {
    for (;;) {
      const auto nl = buffer_.find('\n', scanned_);
      if (nl != std::string::npos) {
        line.assign(buffer_, 0, nl);
        buffer_.erase(0, nl + 1);
        scanned_ = 0;
        return true;
      }
      scanned_ = buffer_.size();
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, timeout_ms) <= 0) return false;
      char chunk[8192];
      const ssize_t n = ::recv(fd_, chunk, sizeof(chunk), 0);
      if (n <= 0) return false;
      buffer_.append(chunk, static_cast<std::size_t>(n));
    }
  }

 private:
  int fd_ = -1;
  std::string buffer_;
  std::size_t scanned_ = 0;
};

struct ClientResult {
  std::vector<std::uint32_t> latency_ns;  // capped at ~4.3 s, more than any read timeout
  std::uint64_t errors = 0;
};

void run_client(const Options& o, Clock::time_point start, Clock::time_point end,
                ClientResult& out) {
  Connection c(o.socket);
  std::string line;
  if (!c.ok() || !c.read_line(line) || line.find("\"VERSION\"") == std::string::npos) {
    ++out.errors;
    return;
  }
  while (Clock::now() < start) std::this_thread::yield();
  const std::string request = o.request + "\n";
  while (Clock::now() < end) {
    const auto t0 = Clock::now();
    if (!c.send(request) || !c.read_line(line)) {
      ++out.errors;
      return;  // the connection is unusable now
    }
    const auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - t0).count();
    if (line.find("\"ESTIMATE\"") == std::string::npos) ++out.errors;
    out.latency_ns.push_back(static_cast<std::uint32_t>(std::min<std::int64_t>(ns, UINT32_MAX)));
  }
}

void run_watcher(const Options& o, Clock::time_point end, std::uint64_t& lines,
                 std::uint64_t& errors) {
  Connection c(o.socket);
  std::string line;
  if (!c.ok() || !c.read_line(line)) {
    ++errors;
    return;
  }
  const nlohmann::json request = {{"request", "watch"}, {"rate_hz", o.watch_rate_hz}};
  if (!c.send(request.dump() + "\n")) {
    ++errors;
    return;
  }
  while (Clock::now() < end) {
    if (!c.read_line(line)) {
      ++errors;
      return;
    }
    if (line.find("\"ESTIMATE\"") != std::string::npos) ++lines;
  }
}

// The reference server (--echo-server): answers every line with `reply`, until `stop`.
class EchoServer {
 public:
  explicit EchoServer(const std::string& path) : path_(path) {
    ::unlink(path.c_str());
    listen_fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
    if (listen_fd_ < 0 ||
        ::bind(listen_fd_, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)) != 0 ||
        ::listen(listen_fd_, 1024) != 0) {
      std::fprintf(stderr, "scp-loadgen: cannot listen on %s: %s\n", path.c_str(),
                   std::strerror(errno));
      std::exit(2);
    }
    // About the size of a real ESTIMATE reply (~700 bytes).
    reply_ = "{\"class\":\"ESTIMATE\",\"pad\":\"" + std::string(680, 'x') + "\"}\n";
    thread_ = std::thread([this] { serve(); });
  }
  ~EchoServer() {
    stop_.store(true);
    thread_.join();
    for (const pollfd& p : fds_) ::close(p.fd);
    ::unlink(path_.c_str());
  }

 private:
  void serve() {
    fds_.push_back({listen_fd_, POLLIN, 0});
    std::vector<std::string> pending(1);
    while (!stop_.load()) {
      if (::poll(fds_.data(), fds_.size(), 50) <= 0) continue;
      for (std::size_t i = 0; i < fds_.size(); ++i) {
        if (!(fds_[i].revents & (POLLIN | POLLHUP | POLLERR))) continue;
        if (i == 0) {
          const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
          if (fd < 0) continue;
          const char version[] = "{\"class\":\"VERSION\",\"release\":\"echo\"}\n";
          (void)!::send(fd, version, sizeof(version) - 1, MSG_NOSIGNAL);
          fds_.push_back({fd, POLLIN, 0});
          pending.emplace_back();
          continue;
        }
        char chunk[4096];
        const ssize_t n = ::recv(fds_[i].fd, chunk, sizeof(chunk), 0);
        if (n <= 0) {
          ::close(fds_[i].fd);
          fds_[i].fd = -1;  // poll() ignores negative descriptors
          continue;
        }
        for (ssize_t k = 0; k < n; ++k) {
          if (chunk[k] == '\n')
            (void)!::send(fds_[i].fd, reply_.data(), reply_.size(), MSG_NOSIGNAL);
        }
      }
    }
  }

  std::string path_;
  int listen_fd_ = -1;
  std::string reply_;
  std::vector<pollfd> fds_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

double percentile(const std::vector<std::uint32_t>& sorted, double q) {
  if (sorted.empty()) return std::nan("");
  const auto i = static_cast<std::size_t>(std::min<double>(
      static_cast<double>(sorted.size()) - 1, std::floor(q * static_cast<double>(sorted.size()))));
  return sorted[i] * 1e-3;
}

}  // namespace

int main(int argc, char** argv) {
  const Options o = parse(argc, argv);
  std::unique_ptr<EchoServer> echo;
  if (o.echo_server) echo = std::make_unique<EchoServer>(o.socket);
  // Connections are set up during the first 0.5 s, then everyone starts at once.
  const auto start = Clock::now() + std::chrono::milliseconds(500);
  const auto end = start + std::chrono::duration_cast<Clock::duration>(
                               std::chrono::duration<double>(o.duration_s));
  std::vector<ClientResult> results(static_cast<std::size_t>(o.clients));
  std::vector<std::uint64_t> watch_lines(static_cast<std::size_t>(o.watchers), 0);
  std::vector<std::uint64_t> watch_errors(static_cast<std::size_t>(o.watchers), 0);
  std::vector<std::thread> threads;
  for (auto& r : results) {
    r.latency_ns.reserve(1 << 16);
    threads.emplace_back([&o, start, end, &r] { run_client(o, start, end, r); });
  }
  for (std::size_t i = 0; i < watch_lines.size(); ++i) {
    threads.emplace_back([&o, end, &watch_lines, &watch_errors, i] {
      run_watcher(o, end, watch_lines[i], watch_errors[i]);
    });
  }
  for (auto& t : threads) t.join();
  const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();

  std::vector<std::uint32_t> all;
  std::uint64_t errors = 0;
  for (const auto& r : results) {
    all.insert(all.end(), r.latency_ns.begin(), r.latency_ns.end());
    errors += r.errors;
  }
  std::sort(all.begin(), all.end());
  std::uint64_t lines = 0;
  for (std::size_t i = 0; i < watch_lines.size(); ++i) {
    lines += watch_lines[i];
    errors += watch_errors[i];
  }
  const nlohmann::json out = {
      {"clients", o.clients},
      {"watchers", o.watchers},
      {"duration_s", o.duration_s},
      {"requests", all.size()},
      {"requests_per_s", static_cast<double>(all.size()) / o.duration_s},
      {"p50_us", all.empty() ? nlohmann::json(nullptr) : nlohmann::json(percentile(all, 0.50))},
      {"p99_us", all.empty() ? nlohmann::json(nullptr) : nlohmann::json(percentile(all, 0.99))},
      {"max_us", all.empty() ? nlohmann::json(nullptr) : nlohmann::json(all.back() * 1e-3)},
      {"watch_lines", lines},
      {"watch_lines_per_s", static_cast<double>(lines) / o.duration_s},
      {"errors", errors},
      {"elapsed_s", elapsed}};
  std::printf("%s\n", out.dump().c_str());
  return errors == 0 ? 0 : 1;
}

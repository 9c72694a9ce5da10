#include "daemon/outputs/server/api_server.hpp"

#include <fcntl.h>
#include <spdlog/spdlog.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/timerfd.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <deque>
#include <optional>
#include <stdexcept>
#include <string>
#include <system_error>
#include <thread>
#include <unordered_map>
#include <vector>

#include "common/clock.hpp"
#include "daemon/outputs/server/render.hpp"
#include "daemon/outputs/server/render_health.hpp"
#include "daemon/outputs/server/request.hpp"

namespace scp::daemon::server {
namespace {

using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;

// epoll user data: small ids for the server's own descriptors, larger ones for clients. Ids are
// never reused, so a command answered after its client left cannot reach a newcomer on the same fd.
constexpr std::uint64_t kListenId = 1;
constexpr std::uint64_t kTimerId = 2;
constexpr std::uint64_t kWakeId = 3;
constexpr std::uint64_t kFirstClientId = 16;

constexpr auto kAckTimeout = std::chrono::seconds(2);
constexpr auto kCloseGrace = std::chrono::seconds(1);  // to flush a final ERROR before closing
constexpr auto kAcceptBackoff = milliseconds(100);     // after EMFILE, instead of spinning
constexpr std::size_t kReadChunk = 16384;
constexpr int kReadsPerEvent = 4;  // full reads; then yield to other clients (level-triggered)

std::string errno_text(int err) {
  return std::error_code(err, std::generic_category()).message();
}

struct Client {
  int fd = -1;
  std::optional<PeerIdentity> peer;
  std::string in;
  std::string out;
  Clock::time_point last_request;
  bool watching = false;
  Clock::duration watch_period{};
  Clock::time_point next_watch;
  bool awaiting_ack = false;  // its later requests wait so that replies keep their order
  bool read_eof = false;
  bool closing = false;  // flush what is queued, then close
  Clock::time_point close_deadline;
  bool dead = false;  // swept (closed and erased) after the current event batch
  std::uint32_t events = 0;
};

struct PendingCommand {
  std::uint64_t client = 0;
  std::uint64_t seq = 0;
  RequestKind kind = RequestKind::reset;
  bool enable = false;
  Clock::time_point deadline;
  bool pushed = false;
  CommandRecord record;  // for the audit trail
};

CommandKind command_kind(RequestKind kind, bool enable) noexcept {
  switch (kind) {
    case RequestKind::excitation:
      return enable ? CommandKind::excitation_on : CommandKind::excitation_off;
    case RequestKind::clear_fault:
      return CommandKind::clear_fault;
    default:
      return CommandKind::reset;
  }
}

void close_fd(int& fd) noexcept {
  if (fd >= 0) ::close(fd);
  fd = -1;
}

sockaddr_un socket_address(const std::string& path) {
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  if (path.empty() || path.size() >= sizeof(addr.sun_path))
    throw std::runtime_error("socket.path '" + path + "' must be 1.." +
                             std::to_string(sizeof(addr.sun_path) - 1) +
                             " characters long; choose a shorter path");
  path.copy(addr.sun_path, path.size());
  return addr;
}

constexpr const char* kNoHealth =
    "health monitoring needs the refinement: set refine.enabled: true (docs/health.md)";

// HEALTH (the monitor's view in full) or BASELINE (the baseline file's contents).
std::string health_reply(RequestKind kind, const HealthControl* health) {
  if (health == nullptr) return render_error(kNoHealth);
  nlohmann::json out;
  if (kind == RequestKind::health) {
    out = health_json(health->view(), /*full=*/true);
    out["class"] = "HEALTH";
  } else {
    out = health->baseline();
    out["class"] = "BASELINE";
  }
  return out.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) + '\n';
}

}  // namespace

struct ApiServer::Impl {
  Impl(ServerSettings s, ServerInfo i, const rt::Seqlock<PublishedState>& st, CommandRing& r,
       const rt::Seqlock<refine::RefinedView>* rf, const rt::LatencyHistogram* lt)
      : settings(std::move(s)), info(std::move(i)), state(st), ring(r), refined(rf), lateness(lt) {
    if (lateness != nullptr) lateness_copy = std::make_unique<rt::LatencyHistogram::Snapshot>();
  }

  ServerSettings settings;
  ServerInfo info;
  const rt::Seqlock<PublishedState>& state;
  CommandRing& ring;
  const rt::Seqlock<refine::RefinedView>* refined;
  const rt::LatencyHistogram* lateness;
  HealthControl* health = nullptr;
  std::unique_ptr<rt::LatencyHistogram::Snapshot> lateness_copy;  // 30 KiB, reused

  // The ESTIMATE line changes only when the loop publishes (once a cycle), while clients may ask
  // many times a cycle: it is rendered once per publication and served from here. The key is
  // read before the snapshot, so the cached line is never older than its key.
  std::string estimate_cache;
  std::uint64_t estimate_cache_state = 0;
  std::uint64_t estimate_cache_refined = 0;
  std::uint64_t estimate_cache_health = 0;
  bool estimate_cache_valid = false;

  // Both published snapshots, read together.
  const std::string& estimate_reply() {
    const std::uint64_t state_version = state.version();
    const std::uint64_t refined_version = refined != nullptr ? refined->version() : 0;
    const std::uint64_t health_version = health != nullptr ? health->version() : 0;
    if (estimate_cache_valid && state_version == estimate_cache_state &&
        refined_version == estimate_cache_refined && health_version == estimate_cache_health) {
      return estimate_cache;
    }
    const PublishedState now = state.load();
    const std::optional<health::HealthView> health_view = health_snapshot();
    const health::HealthView* h = health_view ? &*health_view : nullptr;
    if (refined == nullptr) {
      estimate_cache = render_estimate(now.estimate, nullptr, now.uptime_s, h);
    } else {
      const refine::RefinedView view = refined->load();
      estimate_cache = render_estimate(now.estimate, &view, now.uptime_s, h);
    }
    estimate_cache_state = state_version;
    estimate_cache_refined = refined_version;
    estimate_cache_health = health_version;
    estimate_cache_valid = true;
    return estimate_cache;
  }
  std::string status_reply() {
    const PublishedState now = state.load();
    const rt::LatencyHistogram::Snapshot* fine = nullptr;
    if (lateness != nullptr) {
      lateness->snapshot(*lateness_copy);
      fine = lateness_copy.get();
    }
    const CommandRecord* command = last_command ? &*last_command : nullptr;
    const std::optional<health::HealthView> health_view = health_snapshot();
    const health::HealthView* h = health_view ? &*health_view : nullptr;
    if (refined == nullptr) return render_status(now, info, nullptr, fine, command, h);
    const refine::RefinedView view = refined->load();
    return render_status(now, info, &view, fine, command, h);
  }
  std::optional<health::HealthView> health_snapshot() const {
    if (health == nullptr) return std::nullopt;
    return health->view();
  }
  bool handle_health(Client& client, const ParsedRequest& request, CommandRecord& record);
  // The audit trail: every outcome of a mutating request is logged and the latest kept.
  std::optional<CommandRecord> last_command;
  void audit(CommandRecord record, CommandOutcome outcome, std::string message) {
    record.outcome = outcome;
    record.message = std::move(message);
    log_audit(record);
    last_command = std::move(record);
  }
  AuthPolicy policy;

  int listen_fd = -1;
  int epoll_fd = -1;
  int timer_fd = -1;
  int wake_fd = -1;
  bool bound = false;
  ino_t socket_inode = 0;
  std::thread thread;
  std::atomic<bool> running{false};
  std::atomic<std::size_t> clients_now{0};

  std::unordered_map<std::uint64_t, Client> clients;
  std::deque<PendingCommand> commands;
  std::vector<std::uint64_t> resume;  // clients whose command was answered: process their input
  std::uint64_t next_client_id = kFirstClientId;
  std::uint64_t next_seq = 1;
  Clock::duration tick{};
  bool accept_paused = false;
  Clock::time_point accept_resume;
  std::size_t output_cap = 0;  // per client, from the output budget (settings.hpp)
  Clock::time_point refusal_window_start;
  // When the current epoll_wait returned: the time of every request in its batch. Its uses
  // (idle timeout, watch phase, a command's deadline) need milliseconds, and a clock read per
  // request showed in the server's profile under many clients.
  Clock::time_point batch_now;
  int refusals_logged = 0;
  std::uint64_t refusals_suppressed = 0;

  void start();
  void stop() noexcept;
  void run() noexcept;
  void dispatch(const epoll_event& event);
  void on_accept();
  void on_client(std::uint64_t id, Client& client, std::uint32_t events);
  void on_tick();
  void read_client(std::uint64_t id, Client& client);
  void process_lines(std::uint64_t id, Client& client);
  void handle_line(std::uint64_t id, Client& client, std::string_view line);
  void send(Client& client, std::string_view text);
  // Sends what the socket takes now; returns the bytes sent (marks the client dead on an error).
  std::size_t send_some(Client& client, std::string_view text);
  void flush(Client& client);
  void log_refusal(const std::optional<PeerIdentity>& peer, const std::string& what);
  bool refusal_may_log(Clock::time_point now);
  void update_events(std::uint64_t id, Client& client);
  void begin_close(Client& client, std::string_view error_message);
  void service_commands(Clock::time_point now);
  void answer(std::uint64_t id, const std::string& text);
  void sweep();
  void rearm_timer();
};

// ---- lifecycle --------------------------------------------------------------------------------

void ApiServer::Impl::start() {
  if (thread.joinable()) throw std::runtime_error("ApiServer::start() called twice");
  policy.daemon_uid = ::geteuid();
  if (!settings.group.empty()) {
    policy.group = resolve_group(settings.group);
    policy.group_name = settings.group;
  }
  const std::string& path = settings.socket_path;
  const sockaddr_un addr = socket_address(path);
  output_cap =
      std::min(settings.max_output_bytes,
               settings.output_budget_bytes /
                   std::max<std::size_t>(1, settings.max_clients + settings.privileged_reserve));

  struct stat st {};
  if (::lstat(path.c_str(), &st) == 0) {
    if (!S_ISSOCK(st.st_mode))
      throw std::runtime_error("socket.path " + path +
                               " exists and is not a socket; remove it or choose another path");
    // A socket file outlives a crashed daemon. Only a refused connection proves it is stale.
    const int probe = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (probe < 0) throw std::runtime_error("cannot create a socket: " + errno_text(errno));
    const int rc = ::connect(probe, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr));
    const int err = errno;
    ::close(probe);
    if (rc == 0)
      throw std::runtime_error("another daemon is already listening on " + path +
                               "; stop it first (systemctl stop scp-estimatord) or set "
                               "socket.path to another path");
    if (err != ECONNREFUSED && err != ENOENT)
      throw std::runtime_error("cannot check the existing socket " + path + ": " + errno_text(err) +
                               "; remove it by hand if no daemon uses it");
    if (::unlink(path.c_str()) != 0 && errno != ENOENT)
      throw std::runtime_error("cannot remove the stale socket " + path + ": " + errno_text(errno) +
                               "; remove it by hand or run as root");
  }

  try {
    listen_fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (listen_fd < 0) throw std::runtime_error("cannot create a socket: " + errno_text(errno));
    if (::bind(listen_fd, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)) != 0) {
      const int err = errno;
      std::string remedy = "check socket.path";
      if (err == ENOENT)
        remedy =
            "its directory does not exist; create it, or let systemd do it with "
            "RuntimeDirectory=scp-estimator in the unit";
      else if (err == EACCES || err == EPERM)
        remedy =
            "the daemon's user cannot write to that directory; run as root or choose a "
            "writable socket.path";
      throw std::runtime_error("cannot bind " + path + ": " + errno_text(err) + "; " + remedy);
    }
    bound = true;
    if (::lstat(path.c_str(), &st) == 0) socket_inode = st.st_ino;
    if (::chmod(path.c_str(), static_cast<mode_t>(settings.mode & 07777)) != 0)
      throw std::runtime_error("cannot chmod " + path + ": " + errno_text(errno) +
                               "; check socket.mode");
    if (policy.group && ::chown(path.c_str(), static_cast<uid_t>(-1), *policy.group) != 0)
      throw std::runtime_error("cannot give " + path + " to group " + settings.group + ": " +
                               errno_text(errno) +
                               "; run the daemon as root or as a member of that group");
    if (::listen(listen_fd, SOMAXCONN) != 0)
      throw std::runtime_error("cannot listen on " + path + ": " + errno_text(errno));

    epoll_fd = ::epoll_create1(EPOLL_CLOEXEC);
    timer_fd = ::timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC);
    wake_fd = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
    if (epoll_fd < 0 || timer_fd < 0 || wake_fd < 0)
      throw std::runtime_error("cannot create the server's epoll/timer/event descriptors: " +
                               errno_text(errno));
    const std::pair<int, std::uint64_t> watched[] = {
        {listen_fd, kListenId}, {timer_fd, kTimerId}, {wake_fd, kWakeId}};
    for (const auto& [fd, id] : watched) {
      epoll_event ev{};
      ev.events = EPOLLIN;
      ev.data.u64 = id;
      if (::epoll_ctl(epoll_fd, EPOLL_CTL_ADD, fd, &ev) != 0)
        throw std::runtime_error("epoll_ctl failed: " + errno_text(errno));
    }
    rearm_timer();
    running = true;
    thread = std::thread([this] { run(); });
  } catch (...) {
    stop();
    throw;
  }
}

void ApiServer::Impl::stop() noexcept {
  running = false;
  if (thread.joinable()) {
    const std::uint64_t one = 1;
    [[maybe_unused]] const auto n = ::write(wake_fd, &one, sizeof(one));
    thread.join();
  }
  for (auto& [id, client] : clients) close_fd(client.fd);
  clients.clear();
  commands.clear();
  clients_now = 0;
  close_fd(listen_fd);
  close_fd(epoll_fd);
  close_fd(timer_fd);
  close_fd(wake_fd);
  if (bound) {
    // Remove the file only if it is still ours: a successor may already have replaced it.
    struct stat st {};
    if (::lstat(settings.socket_path.c_str(), &st) == 0 && st.st_ino == socket_inode)
      ::unlink(settings.socket_path.c_str());
    bound = false;
  }
}

void ApiServer::Impl::run() noexcept {
  std::array<epoll_event, 64> events{};
  while (running.load(std::memory_order_relaxed)) {
    const int n = ::epoll_wait(epoll_fd, events.data(), static_cast<int>(events.size()), 1000);
    batch_now = Clock::now();
    if (n < 0) {
      if (errno == EINTR) continue;
      spdlog::error("socket server: epoll_wait failed: {}; the API is down", errno_text(errno));
      return;
    }
    for (int i = 0; i < n; ++i) {
      try {
        dispatch(events[static_cast<std::size_t>(i)]);
      } catch (const std::exception& error) {
        // One request must never take the server down (e.g. bad_alloc on a huge reply).
        spdlog::warn("socket server: {}", error.what());
      }
    }
    try {
      sweep();
      rearm_timer();
    } catch (const std::exception& error) {
      spdlog::warn("socket server: {}", error.what());
    }
  }
}

void ApiServer::Impl::dispatch(const epoll_event& event) {
  switch (event.data.u64) {
    case kListenId:
      on_accept();
      return;
    case kTimerId:
      on_tick();
      return;
    case kWakeId: {
      std::uint64_t value = 0;
      [[maybe_unused]] const auto n = ::read(wake_fd, &value, sizeof(value));
      return;
    }
    default:
      break;
  }
  const auto it = clients.find(event.data.u64);
  if (it == clients.end() || it->second.dead) return;
  try {
    on_client(it->first, it->second, event.events);
  } catch (...) {
    it->second.dead = true;
    throw;
  }
}

// ---- clients ----------------------------------------------------------------------------------

void ApiServer::Impl::on_accept() {
  for (;;) {
    const int fd = ::accept4(listen_fd, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
    if (fd < 0) {
      const int err = errno;
      if (err == EAGAIN || err == EWOULDBLOCK) return;
      if (err == EINTR || err == ECONNABORTED) continue;
      if (err == EMFILE || err == ENFILE || err == ENOBUFS || err == ENOMEM) {
        // The pending connection stays queued and would wake us forever; back off instead.
        spdlog::warn(
            "socket server: cannot accept: {}; raise LimitNOFILE or lower "
            "socket.max_clients",
            errno_text(err));
        epoll_event ev{};
        ev.data.u64 = kListenId;
        ::epoll_ctl(epoll_fd, EPOLL_CTL_MOD, listen_fd, &ev);
        accept_paused = true;
        accept_resume = Clock::now() + kAcceptBackoff;
        return;
      }
      spdlog::warn("socket server: accept failed: {}", errno_text(err));
      return;
    }
    std::optional<PeerIdentity> peer = peer_identity(fd);
    const bool privileged = peer && is_privileged(*peer, policy);
    const std::size_t limit = settings.max_clients + (privileged ? settings.privileged_reserve : 0);
    if (clients.size() >= limit) {
      const std::string text =
          render_error("too many clients: " + std::to_string(clients.size()) +
                       " already connected (socket.max_clients " +
                       std::to_string(settings.max_clients) + "); try again later");
      [[maybe_unused]] const auto n = ::send(fd, text.data(), text.size(), MSG_NOSIGNAL);
      ::close(fd);
      log_refusal(peer, "too many clients");
      continue;
    }
    const std::uint64_t id = next_client_id++;
    Client& client = clients[id];
    client.fd = fd;
    client.peer = std::move(peer);
    client.last_request = Clock::now();
    clients_now = clients.size();
    epoll_event ev{};
    ev.events = EPOLLIN;
    ev.data.u64 = id;
    if (::epoll_ctl(epoll_fd, EPOLL_CTL_ADD, fd, &ev) != 0) {
      client.dead = true;
      continue;
    }
    client.events = EPOLLIN;
    send(client, render_version(info.release));
  }
}

void ApiServer::Impl::on_client(std::uint64_t id, Client& client, std::uint32_t events) {
  if (events & EPOLLIN) read_client(id, client);
  if (!client.dead && (events & EPOLLOUT)) flush(client);
  if (events & EPOLLERR) client.dead = true;
  // HUP without readable data: the peer is gone in both directions.
  if ((events & EPOLLHUP) && !(events & EPOLLIN)) client.dead = true;
  if (!client.dead) update_events(id, client);
}

void ApiServer::Impl::read_client(std::uint64_t id, Client& client) {
  char buffer[kReadChunk];
  for (int i = 0; i < kReadsPerEvent; ++i) {
    if (client.dead || client.closing || client.awaiting_ack || client.read_eof) return;
    const ssize_t n = ::recv(client.fd, buffer, sizeof(buffer), 0);
    if (n > 0) {
      client.in.append(buffer, static_cast<std::size_t>(n));
      process_lines(id, client);
      // A short read emptied the socket: another recv would only say EAGAIN, a system call for
      // nothing. epoll is level-triggered, so what arrives later is reported again.
      if (static_cast<std::size_t>(n) < sizeof(buffer)) return;
    } else if (n == 0) {
      client.read_eof = true;
      process_lines(id, client);
      return;
    } else if (errno == EINTR) {
      continue;
    } else {
      if (errno != EAGAIN && errno != EWOULDBLOCK) client.dead = true;
      return;
    }
  }
}

void ApiServer::Impl::process_lines(std::uint64_t id, Client& client) {
  std::size_t start = 0;
  bool too_long = false;
  while (!client.dead && !client.closing && !client.awaiting_ack) {
    const std::size_t newline = client.in.find('\n', start);
    if (newline == std::string::npos) break;
    if (newline - start > settings.max_line) {
      too_long = true;
      break;
    }
    const std::string_view line(client.in.data() + start, newline - start);
    start = newline + 1;
    handle_line(id, client, line);
  }
  client.in.erase(0, start);
  if (!too_long && client.in.size() > settings.max_line &&
      client.in.find('\n') == std::string::npos)
    too_long = true;
  if (too_long && !client.closing) {
    client.in.clear();
    begin_close(client, "line too long: more than " + std::to_string(settings.max_line) +
                            " bytes without a newline; send one JSON request per line of at "
                            "most " +
                            std::to_string(settings.max_line) + " bytes. Closing the connection");
    return;
  }
  // A client that sent its requests and half-closed still gets its answers, then EOF.
  if (client.read_eof && !client.awaiting_ack && !client.watching && !client.closing &&
      client.in.find('\n') == std::string::npos)
    begin_close(client, {});
}

void ApiServer::Impl::handle_line(std::uint64_t id, Client& client, std::string_view line) {
  if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
  if (line.empty()) return;
  const Clock::time_point now = batch_now;
  client.last_request = now;
  const ParsedRequest request = parse_request(line);
  if (!request.ok) {
    send(client, render_error(request.error));
    return;
  }
  switch (request.kind) {
    case RequestKind::status:
      send(client, status_reply());
      return;
    case RequestKind::estimate:
      send(client, estimate_reply());
      return;
    case RequestKind::watch:
      client.watching = request.enable;
      if (request.enable) {
        client.watch_period = std::chrono::duration_cast<Clock::duration>(
            std::chrono::duration<double>(1.0 / request.rate_hz));
        client.next_watch = now;  // the first ESTIMATE follows at the next tick
      }
      send(client, render_watch(request.enable, request.rate_hz));
      return;
    case RequestKind::health:
    case RequestKind::baseline_show:
      send(client, health_reply(request.kind, health));
      return;
    case RequestKind::reset:
    case RequestKind::excitation:
    case RequestKind::clear_fault:
    case RequestKind::health_ack:
    case RequestKind::baseline_save:
    case RequestKind::baseline_clear:
      break;
  }
  const char* name = request_name(request.kind);
  CommandRecord record;
  record.name = request.kind == RequestKind::excitation
                    ? std::string(name) + (request.enable ? " on" : " off")
                    : std::string(name);
  record.peer = client.peer;
  record.unix_ns = clock::unix_ns();
  if (!client.peer || !is_privileged(*client.peer, policy)) {
    const std::string denied = permission_denied_message(name, policy);
    send(client, render_error(denied));
    // Rate-limited like every refusal: an unprivileged flood must not flood the journal.
    if (refusal_may_log(Clock::now())) {
      audit(std::move(record), CommandOutcome::refused, "permission denied");
    } else {
      last_command = std::move(record);
      last_command->outcome = CommandOutcome::refused;
      last_command->message = "permission denied";
    }
    return;
  }
  if (handle_health(client, request, record)) return;
  if (commands.size() >= kCommandRingSize) {
    const std::string busy = "busy: " + std::to_string(commands.size()) +
                             " commands are waiting for the loop; retry '" + name + "' in a moment";
    send(client, render_error(busy));
    audit(std::move(record), CommandOutcome::busy, busy);
    return;
  }
  PendingCommand command;
  command.client = id;
  command.seq = next_seq++;
  command.kind = request.kind;
  command.enable = request.enable;
  command.deadline = now + kAckTimeout;
  command.record = std::move(record);
  commands.push_back(std::move(command));
  client.awaiting_ack = true;
  service_commands(now);
}

// The health requests are carried out here (the monitor's thread picks them up through its
// mailbox), not by the loop: answered and audited at once.
bool ApiServer::Impl::handle_health(Client& client, const ParsedRequest& request,
                                    CommandRecord& record) {
  if (!is_health_command(request.kind)) return false;
  const char* name = request_name(request.kind);
  HealthOutcome outcome;
  if (health == nullptr) {
    outcome.message = kNoHealth;
  } else if (request.kind == RequestKind::health_ack) {
    outcome = health->acknowledge(state.load().uptime_s);
  } else if (request.kind == RequestKind::baseline_save) {
    outcome = health->save_baseline(state.load().uptime_s);
  } else {
    outcome = health->clear_baseline();
  }
  send(client, render_ack(name, outcome.ok, outcome.message));
  audit(std::move(record), outcome.ok ? CommandOutcome::done : CommandOutcome::failed,
        outcome.message);
  return true;
}

void ApiServer::Impl::send(Client& client, std::string_view text) {
  if (client.dead) return;
  // Nothing queued before it: straight from the caller's buffer, and only what the socket did
  // not take is copied (an ESTIMATE line was copied into `out` and erased again otherwise).
  if (client.out.empty()) text.remove_prefix(send_some(client, text));
  client.out.append(text);
  flush(client);
  // A client that stops reading must not make the server hoard memory for it.
  if (client.out.size() > output_cap) {
    client.dead = true;
    log_refusal(client.peer, "dropped: " + std::to_string(client.out.size()) +
                                 " bytes of unread output (per-client cap " +
                                 std::to_string(output_cap) + ")");
  }
}

// Refusals are logged with who asked, at most a few lines per second: a flood of connections
// must not flood the journal too.
bool ApiServer::Impl::refusal_may_log(Clock::time_point now) {
  if (now - refusal_window_start > std::chrono::seconds(1)) {
    if (refusals_suppressed > 0)
      spdlog::warn("socket server: {} more refusals not logged", refusals_suppressed);
    refusal_window_start = now;
    refusals_logged = 0;
    refusals_suppressed = 0;
  }
  if (refusals_logged >= 5) {
    ++refusals_suppressed;
    return false;
  }
  ++refusals_logged;
  return true;
}

void ApiServer::Impl::log_refusal(const std::optional<PeerIdentity>& peer,
                                  const std::string& what) {
  if (!refusal_may_log(Clock::now())) return;
  if (peer) {
    spdlog::warn("socket server: client uid {} pid {}: {}", peer->uid, peer->pid, what);
  } else {
    spdlog::warn("socket server: client of unknown identity: {}", what);
  }
}

std::size_t ApiServer::Impl::send_some(Client& client, std::string_view text) {
  std::size_t sent = 0;
  while (sent < text.size()) {
    const ssize_t n =
        ::send(client.fd, text.data() + sent, text.size() - sent, MSG_NOSIGNAL | MSG_DONTWAIT);
    if (n > 0) {
      sent += static_cast<std::size_t>(n);
    } else if (n < 0 && errno == EINTR) {
      continue;
    } else {
      if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK) client.dead = true;
      break;
    }
  }
  return sent;
}

void ApiServer::Impl::flush(Client& client) {
  client.out.erase(0, send_some(client, client.out));
  // A burst once buffered must not keep its memory for the life of the connection.
  if (client.out.empty() && client.out.capacity() > 65536) std::string().swap(client.out);
  if (client.closing && client.out.empty()) client.dead = true;
}

void ApiServer::Impl::update_events(std::uint64_t id, Client& client) {
  if (client.dead) return;
  std::uint32_t wanted = 0;
  // While a command is pending, later requests stay in the socket: replies keep their order and
  // a flood cannot grow our buffers.
  if (!client.awaiting_ack && !client.read_eof && !client.closing) wanted |= EPOLLIN;
  if (!client.out.empty()) wanted |= EPOLLOUT;
  if (wanted == client.events) return;
  epoll_event ev{};
  ev.events = wanted;
  ev.data.u64 = id;
  if (::epoll_ctl(epoll_fd, EPOLL_CTL_MOD, client.fd, &ev) != 0) {
    client.dead = true;
    return;
  }
  client.events = wanted;
}

void ApiServer::Impl::begin_close(Client& client, std::string_view error_message) {
  if (!error_message.empty()) send(client, render_error(error_message));
  client.closing = true;
  client.watching = false;
  client.close_deadline = Clock::now() + kCloseGrace;
  if (client.out.empty()) client.dead = true;
}

// ---- the loop's commands ------------------------------------------------------------------------

void ApiServer::Impl::answer(std::uint64_t id, const std::string& text) {
  const auto it = clients.find(id);
  if (it == clients.end() || it->second.dead) return;
  it->second.awaiting_ack = false;
  send(it->second, text);
  resume.push_back(id);
}

// One command in flight at a time: the loop publishes a single last_ack, so two commands answered
// in the same cycle would hide one acknowledgement. A command costs about one loop period.
void ApiServer::Impl::service_commands(Clock::time_point now) {
  while (!commands.empty()) {
    PendingCommand& command = commands.front();
    const char* name = request_name(command.kind);
    if (command.pushed) {
      const PublishedState snapshot = state.load();
      if (snapshot.last_ack.seq == command.seq) {
        const std::string_view message(
            snapshot.last_ack.message.data(),
            strnlen(snapshot.last_ack.message.data(), snapshot.last_ack.message.size()));
        answer(command.client, render_ack(name, snapshot.last_ack.ok, message));
        audit(std::move(command.record),
              snapshot.last_ack.ok ? CommandOutcome::done : CommandOutcome::failed,
              std::string(message));
        commands.pop_front();
        continue;
      }
    }
    if (now >= command.deadline) {
      answer(command.client,
             render_error(std::string("the loop did not answer '") + name +
                          "' within 2 s; check 'scp-estimatorctl status' and the daemon's log "
                          "(is the loop stalled or stopping?)"));
      audit(std::move(command.record), CommandOutcome::timeout,
            "the loop did not answer within 2 s");
      commands.pop_front();
      continue;
    }
    if (command.pushed) return;  // wait for the acknowledgement
    if (!ring.try_push(Command{command.seq, command_kind(command.kind, command.enable)})) {
      answer(command.client, render_error(std::string("busy: the loop's command queue is full; "
                                                      "retry '") +
                                          name + "' in a moment"));
      audit(std::move(command.record), CommandOutcome::busy, "the loop's command queue is full");
      commands.pop_front();
      continue;
    }
    command.pushed = true;
    return;
  }
}

// ---- periodic work ------------------------------------------------------------------------------

void ApiServer::Impl::on_tick() {
  std::uint64_t expirations = 0;
  [[maybe_unused]] const auto n = ::read(timer_fd, &expirations, sizeof(expirations));
  const Clock::time_point now = Clock::now();

  if (accept_paused && now >= accept_resume) {
    epoll_event ev{};
    ev.events = EPOLLIN;
    ev.data.u64 = kListenId;
    ::epoll_ctl(epoll_fd, EPOLL_CTL_MOD, listen_fd, &ev);
    accept_paused = false;
  }

  service_commands(now);
  std::vector<std::uint64_t> answered;
  answered.swap(resume);
  for (const std::uint64_t id : answered) {
    const auto it = clients.find(id);
    if (it == clients.end() || it->second.dead) continue;
    process_lines(id, it->second);
    update_events(id, it->second);
  }

  std::string_view estimate_line;  // rendered once per publication, shared by every watcher
  const auto idle_limit = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(settings.idle_timeout_s));
  for (auto& [id, client] : clients) {
    if (client.dead) continue;
    if (client.closing) {
      if (now >= client.close_deadline) client.dead = true;
      continue;
    }
    if (client.watching && now + tick / 2 >= client.next_watch) {
      if (estimate_line.empty()) estimate_line = estimate_reply();
      send(client, estimate_line);
      // Keep the average rate exact; after a long stall restart the phase instead of bursting.
      client.next_watch += client.watch_period;
      if (client.next_watch + client.watch_period < now)
        client.next_watch = now + client.watch_period;
    } else if (!client.watching && !client.awaiting_ack && now - client.last_request > idle_limit) {
      begin_close(client, "idle timeout: no request for " +
                              std::to_string(static_cast<long long>(settings.idle_timeout_s)) +
                              " s (socket.idle_timeout_s); reconnect, or use 'watch' to stay "
                              "connected");
    }
    update_events(id, client);
  }
}

void ApiServer::Impl::sweep() {
  for (auto it = clients.begin(); it != clients.end();) {
    if (it->second.dead) {
      close_fd(it->second.fd);  // closing also removes it from the epoll set
      it = clients.erase(it);
    } else {
      ++it;
    }
  }
  clients_now = clients.size();
}

// The tick paces watch streams and polls for acknowledgements: fast only when something needs it.
void ApiServer::Impl::rearm_timer() {
  Clock::duration wanted = clients.empty() ? milliseconds(200) : milliseconds(50);
  for (const auto& [id, client] : clients) {
    if (!client.watching) continue;
    wanted = std::min<Clock::duration>(
        wanted, client.watch_period < milliseconds(10) ? milliseconds(1) : milliseconds(5));
  }
  if (!commands.empty()) wanted = milliseconds(1);
  if (wanted == tick) return;
  tick = wanted;
  const auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(tick).count();
  itimerspec spec{};
  spec.it_interval.tv_sec = static_cast<time_t>(ns / 1'000'000'000);
  spec.it_interval.tv_nsec = static_cast<long>(ns % 1'000'000'000);
  spec.it_value = spec.it_interval;
  ::timerfd_settime(timer_fd, 0, &spec, nullptr);
}

// ---- public face ------------------------------------------------------------------------------

ApiServer::ApiServer(ServerSettings settings, ServerInfo info,
                     const rt::Seqlock<PublishedState>& state, CommandRing& commands,
                     const rt::Seqlock<refine::RefinedView>* refined,
                     const rt::LatencyHistogram* lateness)
    : impl_(std::make_unique<Impl>(std::move(settings), std::move(info), state, commands, refined,
                                   lateness)) {}

void ApiServer::set_health(HealthControl* health) noexcept {
  impl_->health = health;
}

ApiServer::~ApiServer() {
  stop();
}

void ApiServer::start() {
  impl_->start();
}
void ApiServer::stop() noexcept {
  impl_->stop();
}
std::size_t ApiServer::client_count() const noexcept {
  return impl_->clients_now.load();
}
const AuthPolicy& ApiServer::auth_policy() const noexcept {
  return impl_->policy;
}

}  // namespace scp::daemon::server

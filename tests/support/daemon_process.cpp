#include "tests/support/daemon_process.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <thread>

extern char** environ;

namespace scp::test {

namespace {

using Clock = std::chrono::steady_clock;

std::runtime_error errno_error(const std::string& what) {
  return std::runtime_error(what + ": " + std::strerror(errno));
}

// The child's environment: ours without anything that would make it talk to a real service
// manager, plus the test's additions. Built before fork() (no allocation in the child).
std::vector<std::string> child_environment(const std::vector<std::string>& extra) {
  std::vector<std::string> env;
  for (char** e = environ; *e != nullptr; ++e) {
    const std::string entry(*e);
    if (entry.rfind("NOTIFY_SOCKET=", 0) == 0 || entry.rfind("WATCHDOG_", 0) == 0) continue;
    env.push_back(entry);
  }
  env.insert(env.end(), extra.begin(), extra.end());
  return env;
}

std::vector<char*> c_strings(std::vector<std::string>& strings) {
  std::vector<char*> out;
  for (auto& s : strings) out.push_back(s.data());
  out.push_back(nullptr);
  return out;
}

// fork + exec with stdout/stderr to files; the child dies with the test process.
pid_t spawn(std::vector<std::string> argv, std::vector<std::string> env, const std::string& out,
            const std::string& err, bool append) {
  auto args = c_strings(argv);
  auto envp = c_strings(env);
  const int flags = O_WRONLY | O_CREAT | O_CLOEXEC | (append ? O_APPEND : O_TRUNC);
  const int out_fd = ::open(out.c_str(), flags, 0644);
  const int err_fd = ::open(err.c_str(), flags, 0644);
  if (out_fd < 0 || err_fd < 0) throw errno_error("cannot open " + out + " or " + err);
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid < 0) throw errno_error("fork");
  if (pid == 0) {
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (::getppid() != parent) ::_exit(127);
    ::dup2(out_fd, 1);
    ::dup2(err_fd, 2);
    const int null_fd = ::open("/dev/null", O_RDONLY);
    if (null_fd >= 0) ::dup2(null_fd, 0);
    sigset_t none;
    sigemptyset(&none);
    ::sigprocmask(SIG_SETMASK, &none, nullptr);
    ::execve(args[0], args.data(), envp.data());
    ::_exit(127);
  }
  ::close(out_fd);
  ::close(err_fd);
  return pid;
}

// waitpid with a timeout; returns the raw status.
std::optional<int> wait_child(pid_t pid, Seconds timeout) {
  const auto end = Clock::now() + timeout;
  for (;;) {
    int status = 0;
    const pid_t r = ::waitpid(pid, &status, WNOHANG);
    if (r == pid) return status;
    if (r < 0) return std::nullopt;
    if (Clock::now() > end) return std::nullopt;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
}

}  // namespace

std::string estimatord_path() {
  return SCP_ESTIMATORD_PATH;
}
std::string estimatorctl_path() {
  return SCP_ESTIMATORCTL_PATH;
}

void sleep_s(double seconds) {
  std::this_thread::sleep_for(Seconds(seconds));
}

TempDir::TempDir() {
  char pattern[] = "/tmp/scp-e2e-XXXXXX";
  if (::mkdtemp(pattern) == nullptr) throw errno_error("mkdtemp");
  path_ = pattern;
  ::chmod(path_.c_str(), 0755);
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

json merge_config(json base, const json& over) {
  if (!base.is_object() || !over.is_object()) return over;
  for (auto it = over.begin(); it != over.end(); ++it) {
    base[it.key()] =
        base.contains(it.key()) ? merge_config(base[it.key()], it.value()) : it.value();
  }
  return base;
}

json base_config(const std::string& dir) {
  return json{
      {"loop",
       {{"period_s", 0.001},
        {"realtime", {{"priority", 0}, {"lock_memory", false}, {"prefault_heap_mib", 0}}}}},
      {"actuator", {{"ambient_c", 25.0}, {"mass_kg", 0.1}, {"resistance_ohm", 1.0}}},
      {"driver", {{"type", "sim"}, {"sim", {{"substeps", 20}}}}},
      {"estimator",
       {{"beta", 3.0},
        {"forgetting", 0.8},
        {"scale", {1000, 1, 1000, 0.1, 0.1, 1}},
        {"p0", 100.0},
        {"p_max", 1.0e10},
        {"theta0", {0, 0, 0, 0, 0, 0}}}},
      {"excitation", {{"enabled", true}, {"profile", "paper"}}},
      {"safety",
       {{"voltage_max_v", 3.3},
        {"temperature_max_c", 150.0},
        {"temperature_min_c", -20.0},
        {"position_abs_max_m", 0.05},
        {"stale_timeout_s", 0.02}}},
      {"socket", {{"path", dir + "/d.sock"}, {"group", ""}, {"mode", "0660"}}},
      {"state",
       {{"directory", dir + "/state"}, {"checkpoint_interval_s", 60}, {"warm_start", true}}},
      {"log_level", "info"}};
}

void write_config(const std::string& path, const json& config) {
  write_text(path, config.dump(2) + "\n");  // JSON is YAML (flow style)
}

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void write_text(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << text;
  if (!out) throw std::runtime_error("cannot write " + path);
}

// ---------------------------------------------------------------------------------------------
Client::Client(const std::string& socket_path, bool read_version) {
  fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd_ < 0) throw errno_error("socket");
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::snprintf(addr.sun_path, sizeof addr.sun_path, "%s", socket_path.c_str());
  if (::connect(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    const auto e = errno_error("connect " + socket_path);
    ::close(fd_);
    fd_ = -1;
    throw e;
  }
  if (read_version) {
    const json v = read_json();
    if (v.value("class", "") != "VERSION") throw std::runtime_error("no VERSION: " + v.dump());
  }
}

Client::~Client() {
  if (fd_ >= 0) ::close(fd_);
}

bool Client::send_raw(const std::string& bytes) {
  std::size_t done = 0;
  const auto end = Clock::now() + Seconds(5);
  while (done < bytes.size()) {
    const ssize_t n = ::send(fd_, bytes.data() + done, bytes.size() - done, MSG_NOSIGNAL);
    if (n > 0) {
      done += static_cast<std::size_t>(n);
      continue;
    }
    if (n < 0 && (errno == EINTR)) continue;
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK) && Clock::now() < end) {
      pollfd p{fd_, POLLOUT, 0};
      ::poll(&p, 1, 50);
      continue;
    }
    return false;
  }
  return true;
}

std::optional<std::string> Client::read_line(Seconds timeout, bool* timed_out) {
  if (timed_out != nullptr) *timed_out = false;
  const auto end = Clock::now() + std::chrono::duration_cast<Clock::duration>(timeout);
  for (;;) {
    const auto nl = buffer_.find('\n');
    if (nl != std::string::npos) {
      std::string line = buffer_.substr(0, nl);
      buffer_.erase(0, nl + 1);
      return line;
    }
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(end - Clock::now());
    if (left.count() <= 0) {
      if (timed_out != nullptr) *timed_out = true;
      return std::nullopt;
    }
    pollfd p{fd_, POLLIN, 0};
    const int r = ::poll(&p, 1, static_cast<int>(left.count()));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) continue;
    char chunk[65536];
    const ssize_t n = ::recv(fd_, chunk, sizeof chunk, MSG_DONTWAIT);
    if (n < 0 && (errno == EAGAIN || errno == EINTR)) continue;
    if (n <= 0) return std::nullopt;  // EOF or reset
    buffer_.append(chunk, static_cast<std::size_t>(n));
  }
}

json Client::read_json(Seconds timeout) {
  bool timed_out = false;
  auto line = read_line(timeout, &timed_out);
  if (!line)
    throw std::runtime_error(timed_out ? "no reply within the timeout" : "connection closed");
  return json::parse(*line);
}

json Client::request(const json& req, Seconds timeout) {
  if (!send_raw(req.dump() + "\n")) throw std::runtime_error("send failed: " + req.dump());
  const bool want_estimate = req.value("request", "") == "estimate";
  const auto end = Clock::now() + std::chrono::duration_cast<Clock::duration>(timeout);
  for (;;) {
    json reply = read_json(std::chrono::duration_cast<Seconds>(end - Clock::now()));
    if (!want_estimate && reply.value("class", "") == "ESTIMATE") continue;
    return reply;
  }
}

// ---------------------------------------------------------------------------------------------
ProcessResult run_process(const std::vector<std::string>& argv, Seconds timeout) {
  char pattern[] = "/tmp/scp-e2e-run-XXXXXX";
  if (::mkdtemp(pattern) == nullptr) throw errno_error("mkdtemp");
  const std::string dir = pattern;
  const pid_t pid = spawn(argv, child_environment({}), dir + "/out", dir + "/err", false);
  ProcessResult result;
  auto status = wait_child(pid, timeout);
  if (!status) {
    ::kill(pid, SIGKILL);
    status = wait_child(pid, Seconds(5));
  }
  if (status && WIFEXITED(*status)) result.exit_code = WEXITSTATUS(*status);
  if (status && WIFSIGNALED(*status)) result.signal = WTERMSIG(*status);
  result.out = read_text(dir + "/out");
  result.err = read_text(dir + "/err");
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);
  return result;
}

// ---------------------------------------------------------------------------------------------
DaemonProcess::DaemonProcess(const TempDir& dir, const json& overrides, DaemonOptions options)
    : config_(merge_config(base_config(dir.path()), overrides)), options_(std::move(options)) {
  socket_path_ = config_["socket"]["path"].get<std::string>();
  state_dir_ = config_["state"]["directory"].get<std::string>();
  config_path_ = dir.file("config.yaml");
  stderr_path_ = dir.file("daemon.stderr");
  std::filesystem::create_directories(state_dir_);
  ::chmod(state_dir_.c_str(), 0755);
  write_config(config_path_, config_);
}

DaemonProcess::~DaemonProcess() {
  kill_now();
}

void DaemonProcess::start() {
  if (pid_ > 0) kill_now();
  const std::string binary = options_.binary.empty() ? estimatord_path() : options_.binary;
  std::vector<std::string> argv{binary, "--config", config_path_};
  argv.insert(argv.end(), options_.extra_args.begin(), options_.extra_args.end());
  pid_ =
      spawn(argv, child_environment(options_.extra_env), stderr_path_ + ".out", stderr_path_, true);
  if (options_.wait_ready) wait_socket(Seconds(15));
}

void DaemonProcess::wait_socket(Seconds timeout) {
  const auto end = Clock::now() + std::chrono::duration_cast<Clock::duration>(timeout);
  while (Clock::now() < end) {
    if (!running()) {
      throw std::runtime_error("scp-estimatord exited during start-up; its log:\n" + stderr_text());
    }
    try {
      Client c(socket_path_);
      return;
    } catch (const std::exception&) {
      sleep_s(0.01);
    }
  }
  throw std::runtime_error("scp-estimatord did not answer on " + socket_path_ + "; its log:\n" +
                           stderr_text());
}

bool DaemonProcess::running() {
  if (pid_ <= 0) return false;
  int status = 0;
  if (::waitpid(pid_, &status, WNOHANG) == 0) return true;
  pid_ = -1;  // exited (or already reaped): remember how
  last_status_ = status;
  return false;
}

void DaemonProcess::signal(int sig) {
  if (pid_ > 0) ::kill(pid_, sig);
}

std::optional<int> DaemonProcess::wait_exit(Seconds timeout) {
  if (pid_ <= 0) {
    if (WIFEXITED(last_status_)) return WEXITSTATUS(last_status_);
    return -1;
  }
  const auto status = wait_child(pid_, timeout);
  if (!status) return std::nullopt;
  pid_ = -1;
  last_status_ = *status;
  return WIFEXITED(*status) ? WEXITSTATUS(*status) : -1;
}

void DaemonProcess::kill_now() {
  if (pid_ <= 0) return;
  ::kill(pid_, SIGKILL);
  int status = 0;
  ::waitpid(pid_, &status, 0);
  last_status_ = status;
  pid_ = -1;
}

std::string DaemonProcess::stderr_text() const {
  return read_text(stderr_path_);
}

bool DaemonProcess::wait_logged(const std::string& text, Seconds timeout) const {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (true) {
    if (stderr_text().find(text) != std::string::npos) return true;
    if (std::chrono::steady_clock::now() >= end) return false;
    sleep_s(0.02);
  }
}

json DaemonProcess::request(const json& req) const {
  Client c(socket_path_);
  return c.request(req);
}

ProcessResult DaemonProcess::run_ctl(const std::vector<std::string>& args, bool as_nobody) const {
  std::vector<std::string> argv;
  if (as_nobody) {
    argv = {"/usr/bin/setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"};
  }
  argv.push_back(estimatorctl_path());
  argv.push_back("--socket");
  argv.push_back(socket_path_);
  argv.insert(argv.end(), args.begin(), args.end());
  return run_process(argv, Seconds(20));
}

}  // namespace scp::test

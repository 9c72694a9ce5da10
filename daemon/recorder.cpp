#include "daemon/recorder.hpp"

#include <cerrno>
#include <charconv>
#include <cstring>
#include <stdexcept>

namespace scp::daemon {

Recorder::Recorder(const std::string& path, RecordRing& ring) : path_(path), ring_(ring) {
  file_ = std::fopen(path.c_str(), "w");
  if (file_ == nullptr) {
    throw std::runtime_error("cannot write the recording " + path + ": " + std::strerror(errno) +
                             " (does the directory exist and is it writable?)");
  }
  // A large buffer: one write(2) per ~1000 rows.
  std::setvbuf(file_, nullptr, _IOFBF, 1 << 20);
  std::fputs(
      "t,x,xdot,T,V,V_cmd,theta_hat1,theta_hat2,theta_hat3,theta_hat4,theta_hat5,theta_hat6,"
      "sigma1,sigma2,sigma3,sigma4,sigma5,sigma6,eps1,eps2,af1,af2,af_hat1,af_hat2,state\n",
      file_);
  thread_ = std::thread([this] { run(); });
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

void Recorder::write_row(const RecordRow& r) {
  // std::to_chars writes the shortest text that reads back as the same double: a replay of this
  // file reproduces the run bit for bit, at a fraction of printf's cost.
  char line[1024];
  char* out = line;
  char* const end = line + sizeof line;
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
  *out++ = '\n';
  const auto size = static_cast<std::size_t>(out - line);
  if (std::fwrite(line, 1, size, file_) != size && write_errno_.load() == 0) {
    write_errno_.store(errno ? errno : EIO);
  }
  rows_.fetch_add(1, std::memory_order_relaxed);
}

void Recorder::finish() {
  if (file_ == nullptr) return;
  stop_.store(true, std::memory_order_release);
  if (thread_.joinable()) thread_.join();
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

// A serial line between two ptys, for Modbus RTU tests with real peers: a bare pty pair (socat's)
// hands a frame over at once, so a master that leaves no silence between frames, or a timeout
// that cannot hold a frame's wire time, goes unseen. Here every byte takes one character time
// ((1 start + data + parity + stop bits) / baud) in its own direction, as on an RS-232 or
// RS-422 link, and reaches the far end when its stop bit would have.
//
// The slave's end is a second pty, or (--slave-port) a TCP connection to a slave that takes its
// RTU frames from a socket (pymodbus's serial server does): a device on a real line has no tty
// layer of its own, whereas a pty passes every byte through the kernel's tty workqueue, whose
// threads run at ordinary priority and are what a loaded machine delays.
//
// It also watches the line as the Modbus serial line specification (V1.02, §2.5.1.1) does: a
// master's frame must begin at least t3.5 after the end of the previous frame on the line, either
// way (3.5 characters, fixed 1.75 ms above 19200 Bd). It prints how many master frames began
// sooner, the shortest silence seen, the longest master frame and how many master frames had each
// length (requests a port held back leave glued together), and the frame counts (all since
// start) on SIGUSR1, and on SIGTERM before it exits.
//
//   usage: serial_line_emulator [--baud B] [--parity N|E|O] [--data-bits D] [--stop-bits S]
//                               [--slave-port PORT] [--trace FILE]
//   prints "PTY is /dev/pts/N" for the slave's end (unless --slave-port), then for the master's
//   end, then "starting data transfer loop" (socat's words, so the tests' helpers read them).
// --trace writes one line per frame: start µs, end µs (since start-up), "M" or "S", hex bytes.

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <deque>
#include <limits>
#include <map>
#include <string>
#include <vector>

namespace {

volatile sig_atomic_t g_stop = 0;
volatile sig_atomic_t g_report = 0;
void on_signal(int sig) {
  (sig == SIGUSR1 ? g_report : g_stop) = 1;
}

std::int64_t now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

struct Options {
  int baud = 115200;
  char parity = 'N';
  int data_bits = 8;
  int stop_bits = 1;
  int slave_port = 0;
  std::string trace;
};

bool parse(int argc, char** argv, Options& o) {
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string key = argv[i];
    const char* value = argv[i + 1];
    if (key == "--baud") {
      o.baud = std::atoi(value);
    } else if (key == "--parity") {
      o.parity = value[0];
    } else if (key == "--data-bits") {
      o.data_bits = std::atoi(value);
    } else if (key == "--stop-bits") {
      o.stop_bits = std::atoi(value);
    } else if (key == "--slave-port") {
      o.slave_port = std::atoi(value);
    } else if (key == "--trace") {
      o.trace = value;
    } else {
      return false;
    }
  }
  return argc % 2 == 1 && o.baud > 0 && (o.parity == 'N' || o.parity == 'E' || o.parity == 'O');
}

// A pty whose master end this program relays; its slave end is held open here too, so that the
// master never reads EIO (a hang-up) between the peer's close and its next open.
struct Pty {
  int master = -1;
  int slave = -1;
  std::string name;
};

bool open_pty(Pty& p) {
  p.master = posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (p.master < 0 || grantpt(p.master) != 0 || unlockpt(p.master) != 0) return false;
  p.name = ptsname(p.master);
  p.slave = open(p.name.c_str(), O_RDWR | O_NOCTTY | O_CLOEXEC);
  if (p.slave < 0) return false;
  // Raw at once: a byte that arrives before the peer configures its end must not be echoed.
  for (const int fd : {p.master, p.slave}) {
    termios t{};
    if (tcgetattr(fd, &t) != 0) return false;
    cfmakeraw(&t);
    if (tcsetattr(fd, TCSANOW, &t) != 0) return false;
  }
  return true;
}

// The slave listening on 127.0.0.1:port; retried for a few seconds while it starts.
int connect_slave(int port) {
  for (int attempt = 0; attempt < 100; ++attempt) {
    const int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0) {
      const int one = 1;
      setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
      fcntl(fd, F_SETFL, O_NONBLOCK);
      return fd;
    }
    ::close(fd);
    usleep(50'000);
  }
  return -1;
}

struct Byte {
  std::uint8_t value;
  std::int64_t end_ns;  // its stop bit has been sent: the far end receives it now
};

struct Frame {
  std::int64_t start_ns = 0;
  std::int64_t end_ns = 0;
  char from = 'M';
  std::vector<std::uint8_t> bytes;
};

// One direction of the line: bytes queue behind each other, each a character time long.
struct Direction {
  int from = -1;
  int to = -1;
  char name = 'M';
  std::deque<Byte> queue;
  std::int64_t line_free_ns = 0;  // when the last queued byte's stop bit ends
};

// Frames as the line shows them, and the master's silences before its frames.
class LineMonitor {
 public:
  LineMonitor(std::int64_t char_ns, std::int64_t t15_ns, std::int64_t t35_ns, bool keep)
      : char_ns_(char_ns), t15_ns_(t15_ns), t35_ns_(t35_ns), keep_(keep) {}

  void on_byte(char from, const Byte& b) {
    const std::int64_t start = b.end_ns - char_ns_;
    // A new frame: the other side spoke last, or this side paused longer than t1.5.
    if (frames_.empty() || frames_.back().from != from || start - frames_.back().end_ns > t15_ns_) {
      if (from == 'M') count_master_frame(start);
      if (!frames_.empty() && frames_.back().from == 'M') ++master_lengths_[master_frame_bytes_];
      if (!keep_ && !frames_.empty()) frames_.pop_front();
      frames_.push_back({start, b.end_ns, from, {}});
      master_frame_bytes_ = 0;
      ++(from == 'M' ? master_frames_ : slave_frames_);
    }
    frames_.back().end_ns = b.end_ns;
    if (from == 'M') {
      ++master_frame_bytes_;
    }
    if (keep_) frames_.back().bytes.push_back(b.value);
  }

  void report(std::FILE* out) const {
    const auto lengths = master_frame_lengths();
    const std::uint64_t longest = lengths.empty() ? 0 : lengths.rbegin()->first;
    std::fprintf(out,
                 "serial line: %llu master frames, %llu slave frames; %llu master frames began "
                 "less than t3.5 (%.0f us) after the previous frame; shortest silence before a "
                 "master frame %.0f us; longest master frame %llu bytes; master frame lengths",
                 static_cast<unsigned long long>(master_frames_),
                 static_cast<unsigned long long>(slave_frames_),
                 static_cast<unsigned long long>(short_silences_), t35_ns_ * 1e-3,
                 master_frames_ < 2 ? 0.0 : shortest_silence_ns_ * 1e-3,
                 static_cast<unsigned long long>(longest));
    for (const auto& [bytes, count] : lengths) {
      std::fprintf(out, " %llux%llu", static_cast<unsigned long long>(bytes),
                   static_cast<unsigned long long>(count));
    }
    std::fputc('\n', out);
  }

  void write_trace(std::FILE* out, std::int64_t t0_ns) const {
    for (const Frame& f : frames_) {
      std::fprintf(out, "%.1f %.1f %c", (f.start_ns - t0_ns) * 1e-3, (f.end_ns - t0_ns) * 1e-3,
                   f.from);
      for (const std::uint8_t v : f.bytes) std::fprintf(out, " %02x", v);
      std::fputc('\n', out);
    }
  }

 private:
  // Bytes -> master frames of that length, the one still on the line included.
  std::map<std::uint64_t, std::uint64_t> master_frame_lengths() const {
    std::map<std::uint64_t, std::uint64_t> lengths = master_lengths_;
    if (!frames_.empty() && frames_.back().from == 'M') ++lengths[master_frame_bytes_];
    return lengths;
  }

  void count_master_frame(std::int64_t start) {
    if (frames_.empty()) return;
    const std::int64_t silence = start - frames_.back().end_ns;
    shortest_silence_ns_ = std::min(shortest_silence_ns_, silence);
    if (silence < t35_ns_) ++short_silences_;
  }

  std::int64_t char_ns_, t15_ns_, t35_ns_;
  bool keep_;
  std::deque<Frame> frames_;
  std::uint64_t master_frames_ = 0, slave_frames_ = 0, short_silences_ = 0;
  // Bytes of the current master frame, and how many ended master frames had each length: more
  // than one request's worth means requests the master's port held back and then sent at once.
  std::uint64_t master_frame_bytes_ = 0;
  std::map<std::uint64_t, std::uint64_t> master_lengths_;
  std::int64_t shortest_silence_ns_ = std::numeric_limits<std::int64_t>::max();
};

// Reads what the sender wrote and queues it on the line behind what is still being sent.
bool take_input(Direction& d, std::int64_t char_ns, LineMonitor& monitor) {
  std::uint8_t buf[512];
  for (;;) {
    const ssize_t n = ::read(d.from, buf, sizeof buf);
    if (n < 0 && (errno == EAGAIN || errno == EINTR || errno == EIO)) return true;
    if (n <= 0) return false;
    const std::int64_t arrived = now_ns();
    for (ssize_t i = 0; i < n; ++i) {
      d.line_free_ns = std::max(d.line_free_ns, arrived) + char_ns;
      d.queue.push_back({buf[i], d.line_free_ns});
      monitor.on_byte(d.name, d.queue.back());
    }
  }
}

// Hands the far end every byte whose stop bit has passed.
void deliver(Direction& d) {
  const std::int64_t now = now_ns();
  std::uint8_t buf[512];
  std::size_t n = 0;
  while (!d.queue.empty() && d.queue.front().end_ns <= now && n < sizeof buf) {
    buf[n++] = d.queue.front().value;
    d.queue.pop_front();
  }
  std::size_t done = 0;
  while (done < n) {
    const ssize_t w = ::write(d.to, buf + done, n - done);
    if (w <= 0) break;  // the far end stopped reading: what it misses is lost, as on a wire
    done += static_cast<std::size_t>(w);
  }
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  if (!parse(argc, argv, o)) {
    std::fprintf(stderr,
                 "usage: serial_line_emulator [--baud B] [--parity N|E|O] [--data-bits D] "
                 "[--stop-bits S] [--trace FILE]\n");
    return 2;
  }
  const int bits = 1 + o.data_bits + (o.parity == 'N' ? 0 : 1) + o.stop_bits;
  const std::int64_t char_ns = 1'000'000'000LL * bits / o.baud;
  // Modbus over serial line V1.02 §2.5.1.1: above 19200 Bd the timers are fixed.
  const std::int64_t t15_ns = o.baud > 19200 ? 750'000 : char_ns * 3 / 2;
  const std::int64_t t35_ns = o.baud > 19200 ? 1'750'000 : char_ns * 7 / 2;

  Pty slave_end, master_end;
  int slave_fd = -1;
  if (o.slave_port > 0) {
    slave_fd = connect_slave(o.slave_port);
  } else if (open_pty(slave_end)) {
    slave_fd = slave_end.master;
    std::printf("PTY is %s\n", slave_end.name.c_str());
  }
  if (slave_fd < 0 || !open_pty(master_end)) {
    std::perror("serial_line_emulator: cannot reach the slave or open a pty");
    return 1;
  }
  std::printf("PTY is %s\nstarting data transfer loop (%d Bd, %lld ns a character)\n",
              master_end.name.c_str(), o.baud, static_cast<long long>(char_ns));
  std::fflush(stdout);
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigaction(SIGTERM, &sa, nullptr);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGUSR1, &sa, nullptr);

  const std::int64_t t0 = now_ns();
  LineMonitor monitor(char_ns, t15_ns, t35_ns, !o.trace.empty());
  Direction to_slave{master_end.master, slave_fd, 'M', {}, 0};
  Direction to_master{slave_fd, master_end.master, 'S', {}, 0};
  while (!g_stop) {
    if (g_report) {
      g_report = 0;
      monitor.report(stdout);
      std::fflush(stdout);
    }
    std::int64_t next = -1;
    for (const Direction* d : {&to_slave, &to_master}) {
      if (!d->queue.empty() && (next < 0 || d->queue.front().end_ns < next)) {
        next = d->queue.front().end_ns;
      }
    }
    pollfd fds[2] = {{master_end.master, POLLIN, 0}, {slave_fd, POLLIN, 0}};
    timespec wait{};
    if (next >= 0) {
      const std::int64_t left = std::max<std::int64_t>(0, next - now_ns());
      wait.tv_sec = static_cast<time_t>(left / 1'000'000'000);
      wait.tv_nsec = static_cast<long>(left % 1'000'000'000);
    }
    const int rc = ppoll(fds, 2, next >= 0 ? &wait : nullptr, nullptr);
    if (rc < 0 && errno != EINTR) break;
    if (rc > 0) {
      if ((fds[0].revents & POLLIN) && !take_input(to_slave, char_ns, monitor)) break;
      if ((fds[1].revents & POLLIN) && !take_input(to_master, char_ns, monitor)) break;
    }
    deliver(to_slave);
    deliver(to_master);
  }
  monitor.report(stdout);
  std::fflush(stdout);
  if (!o.trace.empty()) {
    if (std::FILE* f = std::fopen(o.trace.c_str(), "w")) {
      monitor.write_trace(f, t0);
      std::fclose(f);
    }
  }
  return 0;
}

#include "tools/simdaq/simdaq_server.hpp"

#include <arpa/inet.h>
#include <modbus/modbus.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <set>
#include <thread>
#include <vector>

#include "common/clock.hpp"
#include "drivers/modbus/register_codec.hpp"
#include "drivers/modbus/register_map.hpp"
#include "drivers/modbus/wire_time.hpp"
#include "drivers/sim/sim_driver.hpp"
#include "tools/simdaq/emulated_wire.hpp"

namespace scp::drivers::simdaq {

using modbus::RegisterSignal;
using modbus::Table;

bool encode_sample(const modbus::ModbusSettings& map, const Sample& sample,
                   std::uint16_t* input_registers, int n_input, std::uint16_t* holding_registers,
                   int n_holding) noexcept {
  const std::array<double, modbus::kSignalCount> values = {
      sample.x, sample.xdot, sample.temperature, sample.voltage, sample.current};
  const auto sigs = modbus::signals_of(map);
  bool all_fit = true;
  for (std::size_t i = 0; i < modbus::kSignalCount; ++i) {
    const RegisterSignal& s = *sigs[i];
    if (!s.present) continue;
    const int n = modbus::register_count(s.type);
    std::uint16_t* table = s.table == Table::input ? input_registers : holding_registers;
    const int size = s.table == Table::input ? n_input : n_holding;
    if (s.address + n > size) continue;
    std::array<std::uint16_t, 2> regs{};
    if (s.type == modbus::RegisterType::float32 && !std::isfinite(values[i])) {
      // A float register can carry a failed sensor's NaN (or inf): serve it as such, so the
      // daemon's value checks see what a real DAQ would send (the NaN fault injection).
      const auto word = std::bit_cast<std::uint32_t>(static_cast<float>(values[i]));
      const auto hi = static_cast<std::uint16_t>(word >> 16);
      const auto lo = static_cast<std::uint16_t>(word & 0xFFFFu);
      regs = s.word_order == modbus::WordOrder::ba ? std::array<std::uint16_t, 2>{lo, hi}
                                                   : std::array<std::uint16_t, 2>{hi, lo};
    } else if (!modbus::encode_value(s.type, s.word_order, s.scale, s.offset, values[i],
                                     regs.data())) {
      all_fit = false;
      regs = {};
    }
    std::copy_n(regs.begin(), n, table + s.address);
  }
  return all_fit;
}

double decode_command(const modbus::CommandRegister& command,
                      const std::uint16_t* holding_registers) noexcept {
  const double v =
      modbus::decode_raw(command.type, command.word_order, holding_registers + command.address) *
          command.scale +
      command.offset;
  if (!std::isfinite(v)) return 0.0;
  return std::clamp(v, command.min_volts, command.max_volts);
}

namespace {

// Registers needed to cover every entry of the map in one table.
int table_size(const modbus::ModbusSettings& map, Table table) {
  int size = 1;
  for (const RegisterSignal* s : modbus::signals_of(map)) {
    if (s->present && s->table == table) {
      size = std::max(size, s->address + modbus::register_count(s->type));
    }
  }
  if (table == Table::holding) {
    size = std::max(size, map.command.address + modbus::register_count(map.command.type));
  }
  return size;
}

// Whether a request writes (function 6 or 16) into registers [first, first + count).
bool writes_registers(const std::uint8_t* q, int header, int first, int count) {
  const int function = q[header];
  if (function != 0x06 && function != 0x10) return false;
  const int address = (q[header + 1] << 8) | q[header + 2];
  const int n = function == 0x06 ? 1 : ((q[header + 3] << 8) | q[header + 4]);
  return address < first + count && address + n > first;
}

using Clock = std::chrono::steady_clock;

using clock::monotonic_ns;

// When the kernel received the bytes waiting on TCP socket `fd` (SO_TIMESTAMPNS, peeked), on
// CLOCK_MONOTONIC; 0 if it gave no stamp. A DAQ's line receiver sees a request when it arrives;
// this process, on a loaded machine, may run milliseconds later, and sampling the plant then
// would move the emulated device's instants by its own scheduling, which no real device has.
std::int64_t received_ns(int fd) noexcept {
  char byte = 0;
  iovec iov{&byte, 1};
  alignas(cmsghdr) char control[CMSG_SPACE(sizeof(timespec)) * 2] = {};
  msghdr msg{};
  msg.msg_iov = &iov;
  msg.msg_iovlen = 1;
  msg.msg_control = control;
  msg.msg_controllen = sizeof control;
  if (recvmsg(fd, &msg, MSG_PEEK | MSG_DONTWAIT) <= 0) return 0;
  for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c != nullptr; c = CMSG_NXTHDR(&msg, c)) {
    if (c->cmsg_level != SOL_SOCKET || c->cmsg_type != SCM_TIMESTAMPNS) continue;
    timespec stamp{};
    std::memcpy(&stamp, CMSG_DATA(c), sizeof stamp);
    const std::int64_t real_ns = clock::to_ns(stamp);
    return real_ns == 0 ? 0 : real_ns - clock::unix_ns() + clock::monotonic_ns();
  }
  return 0;
}

void sleep_until_ns(std::int64_t ns) noexcept {
  const timespec ts = clock::to_timespec(ns);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

// Characters of the RTU reply to request `q` (header length `h`): the registers read, or the echo
// of a write; anything else is answered by an exception (5 characters).
int reply_chars(const std::uint8_t* q, int h) noexcept {
  switch (q[h]) {
    case 0x03:
    case 0x04:
      return modbus::read_reply_chars((q[h + 3] << 8) | q[h + 4]);
    case 0x06:
    case 0x10:
      return modbus::write_reply_chars();
    default:
      return 5;
  }
}

}  // namespace

namespace {

// libmodbus's context and register image, freed with the server.
struct ModbusContext {
  ~ModbusContext() {
    if (ctx != nullptr && rtu) modbus_close(ctx);
    if (ctx != nullptr) modbus_free(ctx);
    if (mapping != nullptr) modbus_mapping_free(mapping);
  }
  modbus_t* ctx = nullptr;
  modbus_mapping_t* mapping = nullptr;
  bool rtu = false;
};

struct Counters {
  std::uint64_t requests = 0, dropped = 0, exceptions = 0, unencodable = 0, late = 0,
                watchdog_trips = 0, late_replies = 0;
};

// The simulated DAQ behind a Modbus TCP server or RTU slave: the plant advances by periods of
// wall-clock time (or one period per command in lock-step, or continuously in wall-clock mode),
// its sample sits in the register image, and requests are answered from it, with the faults the
// options ask for.
class ModbusSimDaq {
 public:
  explicit ModbusSimDaq(const SimDaqOptions& o);
  ~ModbusSimDaq();
  // Creates the context and the register image, listens (TCP) or opens the line (RTU), prints
  // the ready line. False (the reason on stderr) when any of it fails.
  bool open();
  void serve(std::atomic<bool>& stop);
  void print_summary() const;

 private:
  bool listen_or_connect();
  bool open_command_log();
  void announce_wallclock() const;
  void step();
  void encode(const Sample& sample);
  // Waits for a request until the next deadline; false on a timeout or a signal.
  bool wait_for_requests(fd_set& fds);
  void check_watchdog();
  void accept_client();
  void handle_request(int fd);
  // False when a fault window swallowed the request or answered it with an exception.
  bool faulted(double t, int header);
  void wallclock_timing(std::int64_t received, int request_bytes);
  bool writes_command() const;
  double commanded() const;
  void log_command(double t, double volts, const char* note);
  double elapsed_s() const { return std::chrono::duration<double>(Clock::now() - start_).count(); }

  const SimDaqOptions& o_;
  const modbus::ModbusSettings& map_;
  const bool tcp_;
  ModbusContext modbus_;
  int n_input_ = 0;
  int n_holding_ = 0;
  int command_count_ = 0;
  int listen_fd_ = -1;
  int rtu_fd_ = -1;
  std::set<int> clients_;
  std::vector<std::uint8_t> query_ = std::vector<std::uint8_t>(MODBUS_MAX_ADU_LENGTH);
  sim::SimDriver plant_;
  Sample sample_;
  std::FILE* log_ = nullptr;
  EmulatedWire wire_;
  WireSettings wire_settings_;
  std::int64_t start_ns_ = 0;  // --wallclock: the plant's time is CLOCK_MONOTONIC since then
  Clock::time_point start_;
  Clock::duration period_{};
  Clock::time_point next_;
  std::int64_t k_ = 0;
  Clock::time_point watchdog_fed_;
  bool watchdog_tripped_ = false;
  Counters n_;
};

WireSettings wire_settings(const SimDaqOptions& o) {
  WireSettings w;
  modbus::ModbusSettings rtu = o.map;
  rtu.transport = modbus::Transport::rtu;  // an RTU line's timing, whatever carries the bytes
  w.char_s = modbus::char_time_s(rtu);
  w.gap_s = o.wire_gap_s >= 0 ? o.wire_gap_s : modbus::kRtuFrameGapChars * w.char_s;
  w.jitter_s = o.wire_jitter_s;
  w.seed = o.wire_seed;
  return w;
}

ModbusSimDaq::ModbusSimDaq(const SimDaqOptions& o)
    : o_(o),
      map_(o.map),
      tcp_(o.map.transport == modbus::Transport::tcp),
      plant_(o.sim),
      wire_(wire_settings(o)),
      wire_settings_(wire_settings(o)) {
  command_count_ = modbus::register_count(map_.command.type);
}

ModbusSimDaq::~ModbusSimDaq() {
  if (log_ != nullptr) std::fclose(log_);
  plant_.close();
  for (const int c : clients_) ::close(c);
  if (listen_fd_ >= 0) ::close(listen_fd_);
}

bool ModbusSimDaq::open() {
  modbus_.rtu = !tcp_;
  modbus_.ctx = tcp_ ? modbus_new_tcp(map_.host.c_str(), map_.port)
                     : modbus_new_rtu(map_.device.c_str(), map_.baud, map_.parity, map_.data_bits,
                                      map_.stop_bits);
  if (modbus_.ctx == nullptr) {
    std::fprintf(stderr, "scp-simdaq: cannot create the Modbus context: %s\n",
                 modbus_strerror(errno));
    return false;
  }
  modbus_set_slave(modbus_.ctx, map_.unit_id);
  // A client that sends half a request must not freeze the plant.
  modbus_set_indication_timeout(modbus_.ctx, 0, 200000);
  n_input_ = table_size(map_, Table::input);
  n_holding_ = std::max(table_size(map_, Table::holding), o_.watchdog_register + 1);
  modbus_.mapping = modbus_mapping_new(0, 0, n_holding_, n_input_);
  if (modbus_.mapping == nullptr) {
    std::fprintf(stderr, "scp-simdaq: cannot allocate the register map: %s\n",
                 modbus_strerror(errno));
    return false;
  }
  if (!listen_or_connect()) return false;
  plant_.open();
  plant_.read({0.0, o_.period_s}, sample_);
  encode(sample_);
  if (!open_command_log()) return false;
  start_ns_ = monotonic_ns();
  announce_wallclock();
  start_ = Clock::now();
  period_ = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o_.period_s));
  next_ = start_ + period_;
  watchdog_fed_ = Clock::now();
  return true;
}

bool ModbusSimDaq::listen_or_connect() {
  if (tcp_) {
    listen_fd_ = modbus_tcp_listen(modbus_.ctx, 4);
    if (listen_fd_ == -1) {
      std::fprintf(stderr, "scp-simdaq: cannot listen on %s:%d: %s (port in use? try --listen)\n",
                   map_.host.c_str(), map_.port, modbus_strerror(errno));
      return false;
    }
    sockaddr_in bound{};
    socklen_t len = sizeof bound;
    getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&bound), &len);
    std::printf("scp-simdaq: listening on %s:%d unit %d, period %g s\n", map_.host.c_str(),
                ntohs(bound.sin_port), map_.unit_id, o_.period_s);
  } else {
    if (modbus_connect(modbus_.ctx) == -1) {
      std::fprintf(stderr, "scp-simdaq: cannot open %s: %s\n", map_.device.c_str(),
                   modbus_strerror(errno));
      return false;
    }
    rtu_fd_ = modbus_get_socket(modbus_.ctx);
    std::printf("scp-simdaq: serving %s %d %c%d%d unit %d, period %g s\n", map_.device.c_str(),
                map_.baud, map_.parity, map_.data_bits, map_.stop_bits, map_.unit_id, o_.period_s);
  }
  std::fflush(stdout);
  return true;
}

bool ModbusSimDaq::open_command_log() {
  if (o_.command_log.empty()) return true;
  log_ = std::fopen(o_.command_log.c_str(), "w");
  if (log_ == nullptr) {
    std::fprintf(stderr, "scp-simdaq: cannot write the command log %s: %s\n",
                 o_.command_log.c_str(), std::strerror(errno));
    return false;
  }
  setvbuf(log_, nullptr, _IOLBF, 0);  // a test may SIGKILL us: every line must be on disk
  return true;
}

void ModbusSimDaq::announce_wallclock() const {
  if (!o_.wallclock) return;
  std::printf("scp-simdaq: wall-clock plant%s", o_.wire ? "" : "\n");
  if (o_.wire) {
    std::printf(
        " behind an emulated RTU line: %.1f us per character, gap %.1f us, jitter %.1f us\n",
        wire_settings_.char_s * 1e6, wire_settings_.gap_s * 1e6, o_.wire_jitter_s * 1e6);
  }
  std::fflush(stdout);
}

void ModbusSimDaq::encode(const Sample& sample) {
  if (!encode_sample(map_, sample, modbus_.mapping->tab_input_registers, n_input_,
                     modbus_.mapping->tab_registers, n_holding_)) {
    ++n_.unencodable;
  }
}

// One period of the plant under the voltage the command register holds now.
void ModbusSimDaq::step() {
  ++k_;
  plant_.write_voltage(decode_command(map_.command, modbus_.mapping->tab_registers));
  plant_.read({static_cast<double>(k_) * o_.period_s, o_.period_s}, sample_);
  encode(sample_);
}

// Whether the request in query_ (function 6 or 16) wrote into the command register.
bool ModbusSimDaq::writes_command() const {
  return writes_registers(query_.data(), modbus_get_header_length(modbus_.ctx),
                          map_.command.address, command_count_);
}

// The voltage the write request in query_ carries for the command register.
double ModbusSimDaq::commanded() const {
  const int header = modbus_get_header_length(modbus_.ctx);
  std::array<std::uint16_t, 2> regs{};
  const int f = query_[static_cast<std::size_t>(header)];
  const int at = header + (f == 0x06 ? 3 : 6);
  for (int i = 0; i < command_count_ && i < 2; ++i) {
    regs[static_cast<std::size_t>(i)] =
        static_cast<std::uint16_t>((query_[static_cast<std::size_t>(at + 2 * i)] << 8) |
                                   query_[static_cast<std::size_t>(at + 2 * i + 1)]);
  }
  modbus::CommandRegister c = map_.command;
  c.address = 0;
  return decode_command(c, regs.data());
}

void ModbusSimDaq::log_command(double t, double volts, const char* note) {
  if (log_ == nullptr) return;
  std::fprintf(log_, "%lld,%.6f,%.9g%s%s\n", static_cast<long long>(k_), t, volts,
               note[0] ? "," : "", note);
}

void ModbusSimDaq::serve(std::atomic<bool>& stop) {
  while (!stop.load()) {
    if (o_.duration_s > 0 && elapsed_s() >= o_.duration_s) break;
    fd_set fds;
    const bool ready = wait_for_requests(fds);
    check_watchdog();
    if (!ready) continue;  // timeout or EINTR (Ctrl-C)
    if (tcp_ && FD_ISSET(listen_fd_, &fds)) accept_client();
    std::vector<int> serve;
    if (tcp_) {
      for (const int c : clients_) {
        if (FD_ISSET(c, &fds)) serve.push_back(c);
      }
    } else if (FD_ISSET(rtu_fd_, &fds)) {
      serve.push_back(rtu_fd_);
    }
    for (const int fd : serve) handle_request(fd);
    if (!tcp_) modbus_set_socket(modbus_.ctx, rtu_fd_);
  }
}

bool ModbusSimDaq::wait_for_requests(fd_set& fds) {
  const auto now = Clock::now();
  // The plant advances by whole periods of wall-clock time; far behind (a suspended process)
  // it catches up at most one second and then resynchronizes instead of spinning.
  int steps = 0;
  while (!o_.lockstep && !o_.wallclock && now >= next_ &&
         steps < static_cast<int>(1.0 / o_.period_s) + 1) {
    step();
    next_ += period_;
    ++steps;
  }
  if (now >= next_) next_ = now + period_;
  // Lock-step: no deadline, only a bound so that Ctrl-C and --duration are seen.
  if (o_.lockstep || o_.wallclock) next_ = now + std::chrono::milliseconds(100);

  FD_ZERO(&fds);
  int max_fd = -1;
  const auto watch = [&](int fd) {
    FD_SET(fd, &fds);
    max_fd = std::max(max_fd, fd);
  };
  if (tcp_) {
    watch(listen_fd_);
    for (const int c : clients_) watch(c);
  } else {
    watch(rtu_fd_);
  }
  const auto wait = std::chrono::duration_cast<std::chrono::microseconds>(next_ - Clock::now());
  timeval tv{0, static_cast<suseconds_t>(std::max<std::int64_t>(0, wait.count()))};
  tv.tv_sec = tv.tv_usec / 1000000;
  tv.tv_usec %= 1000000;
  return select(max_fd + 1, &fds, nullptr, nullptr, &tv) > 0;
}

// The DAQ's own communication watchdog: unfed for watchdog_timeout_s, the output goes to 0 V
// whatever the command register held: the only protection when the link is dead.
void ModbusSimDaq::check_watchdog() {
  if (o_.watchdog_timeout_s <= 0 || watchdog_tripped_ ||
      Clock::now() - watchdog_fed_ <= std::chrono::duration<double>(o_.watchdog_timeout_s)) {
    return;
  }
  watchdog_tripped_ = true;
  ++n_.watchdog_trips;
  std::fill_n(modbus_.mapping->tab_registers + map_.command.address, command_count_,
              std::uint16_t{0});
  log_command(elapsed_s(), decode_command(map_.command, modbus_.mapping->tab_registers),
              "watchdog");
}

void ModbusSimDaq::accept_client() {
  const int c = accept(listen_fd_, nullptr, nullptr);
  if (c < 0) return;
  // Without it Nagle holds a reply sent right after another (a late one) until the client's
  // delayed ACK: one late reply would make the next ones late too.
  const int one = 1;
  setsockopt(c, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  // The plant's instants are those of the request's arrival on this host, not of our wake-up
  // after it (see received_ns).
  setsockopt(c, SOL_SOCKET, SO_TIMESTAMPNS, &one, sizeof one);
  clients_.insert(c);
}

void ModbusSimDaq::handle_request(int fd) {
  modbus_set_socket(modbus_.ctx, fd);
  const std::int64_t received = tcp_ ? received_ns(fd) : 0;
  const int rc = modbus_receive(modbus_.ctx, query_.data());
  if (rc == 0) return;  // RTU: addressed to another unit
  if (rc == -1) {
    if (tcp_) {  // the client went away
      ::close(fd);
      clients_.erase(fd);
    } else {
      modbus_flush(modbus_.ctx);  // a garbled frame: resynchronize on the next one
    }
    return;
  }
  ++n_.requests;
  const double t = elapsed_s();
  const int header = modbus_get_header_length(modbus_.ctx);
  if (faulted(t, header)) return;
  if (o_.watchdog_timeout_s > 0 &&
      (o_.watchdog_register < 0 ||
       writes_registers(query_.data(), header, o_.watchdog_register, 1))) {
    watchdog_fed_ = Clock::now();
    watchdog_tripped_ = false;  // fed again: armed again
  }
  if (o_.wallclock) wallclock_timing(received, rc);
  // Logged before the reply: a test that SIGKILLs us right after the client saw the
  // acknowledgement must find that write in the log.
  const bool command = writes_command();
  if (command) log_command(t, commanded(), "");
  modbus_reply(modbus_.ctx, query_.data(), rc, modbus_.mapping);
  if (o_.wallclock && command) {
    plant_.write_voltage(decode_command(map_.command, modbus_.mapping->tab_registers));
    ++k_;  // from the request's event instant on
  }
  if (command && o_.lockstep) step();  // the reply went out first: the client is not kept waiting
}

bool ModbusSimDaq::faulted(double t, int header) {
  if (in_window(t, o_.fault_after_s, o_.fault_duration_s)) {
    ++n_.dropped;  // a dead slave: the request is read and never answered
    // What the client tried to command, as a DAQ would see it on the wire, not applied.
    if (writes_command()) log_command(t, commanded(), "unanswered");
    return true;
  }
  const std::uint8_t function = query_[static_cast<std::size_t>(header)];
  const bool is_write = function == 0x06 || function == 0x10;
  if (in_window(t, o_.exception_after_s, o_.fault_duration_s) &&
      !(o_.exception_reads_only && is_write)) {
    ++n_.exceptions;
    modbus_reply_exception(modbus_.ctx, query_.data(), static_cast<unsigned>(o_.exception_code));
    return true;
  }
  if (o_.late_every > 0 && n_.requests % static_cast<std::uint64_t>(o_.late_every) == 0) {
    // A late reply: the client has timed out on it and moved on; it must recognise and discard
    // this one when it comes.
    ++n_.late;
    std::this_thread::sleep_for(
        std::chrono::duration<double>(o_.late_factor * map_.response_timeout_s));
  }
  return false;
}

// The request's instant on the (emulated) line: sample the plant then, or bring it there under
// the old command before the new one applies; reply when the line would deliver.
void ModbusSimDaq::wallclock_timing(std::int64_t received, int request_bytes) {
  const int h = modbus_get_header_length(modbus_.ctx);
  const int request_chars = tcp_ ? request_bytes - h + 3 : request_bytes;  // RTU: address+PDU+CRC
  const std::int64_t now_ns = monotonic_ns();
  const std::int64_t arrived = received > 0 && received <= now_ns ? received : now_ns;
  const WireTransaction w =
      o_.wire ? wire_.schedule(arrived, request_chars, reply_chars(query_.data(), h))
              : WireTransaction{arrived, arrived};
  const double t_event = static_cast<double>(w.event_ns - start_ns_) * 1e-9;
  if (writes_command()) {
    plant_.advance_to(t_event);
  } else {
    plant_.read({t_event, o_.period_s}, sample_);
    encode(sample_);
  }
  sleep_until_ns(w.reply_ns);
  // A loaded machine wakes us late: the reply (not the sample) is late, which moves the
  // daemon's transaction midpoint by half of it. Counted for the summary.
  if (monotonic_ns() - w.reply_ns > 500'000) ++n_.late_replies;
}

void ModbusSimDaq::print_summary() const {
  std::printf(
      "scp-simdaq: stopped after %.3f s: %llu requests, %llu unanswered, %llu exception replies, "
      "%llu samples that did not fit their register type, %llu replies sent late, %llu "
      "watchdog trips, %llu replies sent > 0.5 ms after the emulated line would have delivered "
      "them\n",
      elapsed_s(), static_cast<unsigned long long>(n_.requests),
      static_cast<unsigned long long>(n_.dropped), static_cast<unsigned long long>(n_.exceptions),
      static_cast<unsigned long long>(n_.unencodable), static_cast<unsigned long long>(n_.late),
      static_cast<unsigned long long>(n_.watchdog_trips),
      static_cast<unsigned long long>(n_.late_replies));
  std::fflush(stdout);
}

}  // namespace

int serve_modbus(const SimDaqOptions& o, std::atomic<bool>& stop) {
  ModbusSimDaq daq(o);
  if (!daq.open()) return 1;
  daq.serve(stop);
  daq.print_summary();
  return 0;
}

}  // namespace scp::drivers::simdaq

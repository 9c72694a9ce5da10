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
  const std::array<double, modbus::kSignalCount> values = {sample.x, sample.xdot,
                                                           sample.temperature, sample.voltage};
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

int serve_modbus(const SimDaqOptions& o, std::atomic<bool>& stop) {
  const modbus::ModbusSettings& map = o.map;
  const bool tcp = map.transport == modbus::Transport::tcp;
  modbus_t* ctx =
      tcp ? modbus_new_tcp(map.host.c_str(), map.port)
          : modbus_new_rtu(map.device.c_str(), map.baud, map.parity, map.data_bits, map.stop_bits);
  if (ctx == nullptr) {
    std::fprintf(stderr, "scp-simdaq: cannot create the Modbus context: %s\n",
                 modbus_strerror(errno));
    return 1;
  }
  modbus_set_slave(ctx, map.unit_id);
  // A client that sends half a request must not freeze the plant.
  modbus_set_indication_timeout(ctx, 0, 200000);
  const int n_input = table_size(map, Table::input);
  const int n_holding = std::max(table_size(map, Table::holding), o.watchdog_register + 1);
  modbus_mapping_t* mb = modbus_mapping_new(0, 0, n_holding, n_input);
  if (mb == nullptr) {
    std::fprintf(stderr, "scp-simdaq: cannot allocate the register map: %s\n",
                 modbus_strerror(errno));
    modbus_free(ctx);
    return 1;
  }

  int listen_fd = -1;
  int rtu_fd = -1;
  if (tcp) {
    listen_fd = modbus_tcp_listen(ctx, 4);
    if (listen_fd == -1) {
      std::fprintf(stderr, "scp-simdaq: cannot listen on %s:%d: %s (port in use? try --listen)\n",
                   map.host.c_str(), map.port, modbus_strerror(errno));
      modbus_mapping_free(mb);
      modbus_free(ctx);
      return 1;
    }
    sockaddr_in bound{};
    socklen_t len = sizeof bound;
    getsockname(listen_fd, reinterpret_cast<sockaddr*>(&bound), &len);
    std::printf("scp-simdaq: listening on %s:%d unit %d, period %g s\n", map.host.c_str(),
                ntohs(bound.sin_port), map.unit_id, o.period_s);
  } else {
    if (modbus_connect(ctx) == -1) {
      std::fprintf(stderr, "scp-simdaq: cannot open %s: %s\n", map.device.c_str(),
                   modbus_strerror(errno));
      modbus_mapping_free(mb);
      modbus_free(ctx);
      return 1;
    }
    rtu_fd = modbus_get_socket(ctx);
    std::printf("scp-simdaq: serving %s %d %c%d%d unit %d, period %g s\n", map.device.c_str(),
                map.baud, map.parity, map.data_bits, map.stop_bits, map.unit_id, o.period_s);
  }
  std::fflush(stdout);

  sim::SimDriver plant(o.sim);
  plant.open();
  Sample sample;
  plant.read({0.0, o.period_s}, sample);
  encode_sample(map, sample, mb->tab_input_registers, n_input, mb->tab_registers, n_holding);

  std::FILE* log = nullptr;
  if (!o.command_log.empty()) {
    log = std::fopen(o.command_log.c_str(), "w");
    if (log == nullptr) {
      std::fprintf(stderr, "scp-simdaq: cannot write the command log %s: %s\n",
                   o.command_log.c_str(), std::strerror(errno));
      plant.close();
      if (listen_fd >= 0) ::close(listen_fd);
      modbus_free(ctx);
      modbus_mapping_free(mb);
      return 1;
    }
    setvbuf(log, nullptr, _IOLBF, 0);  // a test may SIGKILL us: every line must be on disk
  }

  // --wallclock: the plant's time is CLOCK_MONOTONIC since here, advanced to each request's
  // instant.
  const std::int64_t start_ns = monotonic_ns();
  WireSettings wire_settings;
  wire_settings.char_s = modbus::char_time_s([&] {
    modbus::ModbusSettings rtu = map;
    rtu.transport = modbus::Transport::rtu;  // an RTU line's timing, whatever carries the bytes
    return rtu;
  }());
  wire_settings.gap_s =
      o.wire_gap_s >= 0 ? o.wire_gap_s : modbus::kRtuFrameGapChars * wire_settings.char_s;
  wire_settings.jitter_s = o.wire_jitter_s;
  wire_settings.seed = o.wire_seed;
  EmulatedWire wire(wire_settings);
  if (o.wallclock) {
    std::printf("scp-simdaq: wall-clock plant%s", o.wire ? "" : "\n");
    if (o.wire) {
      std::printf(
          " behind an emulated RTU line: %.1f us per character, gap %.1f us, jitter %.1f us\n",
          wire_settings.char_s * 1e6, wire_settings.gap_s * 1e6, o.wire_jitter_s * 1e6);
    }
    std::fflush(stdout);
  }

  std::set<int> clients;
  std::vector<std::uint8_t> query(MODBUS_MAX_ADU_LENGTH);
  const auto start = Clock::now();
  const auto period =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.period_s));
  auto next = start + period;
  std::int64_t k = 0;
  std::uint64_t requests = 0, dropped = 0, exceptions = 0, unencodable = 0, late_replies = 0;
  // One period of the plant under the voltage the command register holds now.
  const auto step = [&] {
    ++k;
    plant.write_voltage(decode_command(map.command, mb->tab_registers));
    plant.read({static_cast<double>(k) * o.period_s, o.period_s}, sample);
    if (!encode_sample(map, sample, mb->tab_input_registers, n_input, mb->tab_registers,
                       n_holding)) {
      ++unencodable;
    }
  };
  const int command_count = modbus::register_count(map.command.type);
  // Whether a request (function 6 or 16) wrote into the command register.
  const auto writes_command = [&](const std::uint8_t* q) {
    return writes_registers(q, modbus_get_header_length(ctx), map.command.address, command_count);
  };
  // The voltage a write request (function 6 or 16) carries for the command register.
  const auto commanded_in = [&](const std::uint8_t* q, int header) {
    std::array<std::uint16_t, 2> regs{};
    const int f = q[static_cast<std::size_t>(header)];
    const int at = header + (f == 0x06 ? 3 : 6);
    for (int i = 0; i < command_count && i < 2; ++i) {
      regs[static_cast<std::size_t>(i)] =
          static_cast<std::uint16_t>((q[static_cast<std::size_t>(at + 2 * i)] << 8) |
                                     q[static_cast<std::size_t>(at + 2 * i + 1)]);
    }
    modbus::CommandRegister c = map.command;
    c.address = 0;
    return decode_command(c, regs.data());
  };
  const auto log_command = [&](double t, double volts, const char* note) {
    if (log == nullptr) return;
    std::fprintf(log, "%lld,%.6f,%.9g%s%s\n", static_cast<long long>(k), t, volts,
                 note[0] ? "," : "", note);
  };
  std::uint64_t late = 0, watchdog_trips = 0;
  auto watchdog_fed = Clock::now();
  bool watchdog_tripped = false;
  const auto late_delay = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(o.late_factor * map.response_timeout_s));

  while (!stop.load()) {
    auto now = Clock::now();
    const double elapsed = std::chrono::duration<double>(now - start).count();
    if (o.duration_s > 0 && elapsed >= o.duration_s) break;
    // The plant advances by whole periods of wall-clock time; far behind (a suspended process)
    // it catches up at most one second and then resynchronizes instead of spinning.
    int steps = 0;
    while (!o.lockstep && !o.wallclock && now >= next &&
           steps < static_cast<int>(1.0 / o.period_s) + 1) {
      step();
      next += period;
      ++steps;
    }
    if (now >= next) next = now + period;
    // Lock-step: no deadline, only a bound so that Ctrl-C and --duration are seen.
    if (o.lockstep || o.wallclock) next = now + std::chrono::milliseconds(100);

    fd_set fds;
    FD_ZERO(&fds);
    int max_fd = -1;
    const auto watch = [&](int fd) {
      FD_SET(fd, &fds);
      max_fd = std::max(max_fd, fd);
    };
    if (tcp) {
      watch(listen_fd);
      for (const int c : clients) watch(c);
    } else {
      watch(rtu_fd);
    }
    const auto wait = std::chrono::duration_cast<std::chrono::microseconds>(next - Clock::now());
    timeval tv{0, static_cast<suseconds_t>(std::max<std::int64_t>(0, wait.count()))};
    tv.tv_sec = tv.tv_usec / 1000000;
    tv.tv_usec %= 1000000;
    const int ready = select(max_fd + 1, &fds, nullptr, nullptr, &tv);

    // The DAQ's own communication watchdog: unfed for watchdog_timeout_s, the output goes to
    // 0 V whatever the command register held: the only protection when the link is dead.
    if (o.watchdog_timeout_s > 0 && !watchdog_tripped &&
        Clock::now() - watchdog_fed > std::chrono::duration<double>(o.watchdog_timeout_s)) {
      watchdog_tripped = true;
      ++watchdog_trips;
      std::fill_n(mb->tab_registers + map.command.address, command_count, std::uint16_t{0});
      log_command(std::chrono::duration<double>(Clock::now() - start).count(),
                  decode_command(map.command, mb->tab_registers), "watchdog");
    }
    if (ready <= 0) continue;  // timeout or EINTR (Ctrl-C)

    if (tcp && FD_ISSET(listen_fd, &fds)) {
      const int c = accept(listen_fd, nullptr, nullptr);
      if (c >= 0) {
        // Without it Nagle holds a reply sent right after another (a late one) until the
        // client's delayed ACK: one late reply would make the next ones late too.
        const int one = 1;
        setsockopt(c, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
        // The plant's instants are those of the request's arrival on this host, not of our
        // wake-up after it (see received_ns).
        setsockopt(c, SOL_SOCKET, SO_TIMESTAMPNS, &one, sizeof one);
        clients.insert(c);
      }
    }
    std::vector<int> serve;
    if (tcp) {
      for (const int c : clients) {
        if (FD_ISSET(c, &fds)) serve.push_back(c);
      }
    } else if (FD_ISSET(rtu_fd, &fds)) {
      serve.push_back(rtu_fd);
    }
    for (const int fd : serve) {
      modbus_set_socket(ctx, fd);
      const std::int64_t received = tcp ? received_ns(fd) : 0;
      const int rc = modbus_receive(ctx, query.data());
      if (rc == 0) continue;  // RTU: addressed to another unit
      if (rc == -1) {
        if (tcp) {  // the client went away
          ::close(fd);
          clients.erase(fd);
        } else {
          modbus_flush(ctx);  // a garbled frame: resynchronize on the next one
        }
        continue;
      }
      ++requests;
      const double t = std::chrono::duration<double>(Clock::now() - start).count();
      const int header = modbus_get_header_length(ctx);
      if (in_window(t, o.fault_after_s, o.fault_duration_s)) {
        ++dropped;  // a dead slave: the request is read and never answered
        if (writes_command(query.data())) {
          // What the client tried to command, as a DAQ would see it on the wire, not applied.
          log_command(t, commanded_in(query.data(), header), "unanswered");
        }
        continue;
      }
      const bool is_write = query[static_cast<std::size_t>(header)] == 0x06 ||
                            query[static_cast<std::size_t>(header)] == 0x10;
      if (in_window(t, o.exception_after_s, o.fault_duration_s) &&
          !(o.exception_reads_only && is_write)) {
        ++exceptions;
        modbus_reply_exception(ctx, query.data(), static_cast<unsigned>(o.exception_code));
        continue;
      }
      if (o.late_every > 0 && requests % static_cast<std::uint64_t>(o.late_every) == 0) {
        // A late reply: the client has timed out on it and moved on; it must recognise and
        // discard this one when it comes.
        ++late;
        std::this_thread::sleep_for(late_delay);
      }
      if (o.watchdog_timeout_s > 0 &&
          (o.watchdog_register < 0 ||
           writes_registers(query.data(), header, o.watchdog_register, 1))) {
        watchdog_fed = Clock::now();
        watchdog_tripped = false;  // fed again: armed again
      }
      if (o.wallclock) {
        // The request's instant on the (emulated) line: sample the plant then, or bring it there
        // under the old command before the new one applies; reply when the line would deliver.
        const int h = modbus_get_header_length(ctx);
        const int request_chars = tcp ? rc - h + 3 : rc;  // RTU: address + PDU + CRC
        const std::int64_t now_ns = monotonic_ns();
        const std::int64_t arrived = received > 0 && received <= now_ns ? received : now_ns;
        const WireTransaction w =
            o.wire ? wire.schedule(arrived, request_chars, reply_chars(query.data(), h))
                   : WireTransaction{arrived, arrived};
        const double t_event = static_cast<double>(w.event_ns - start_ns) * 1e-9;
        if (writes_command(query.data())) {
          plant.advance_to(t_event);
        } else {
          plant.read({t_event, o.period_s}, sample);
          if (!encode_sample(map, sample, mb->tab_input_registers, n_input, mb->tab_registers,
                             n_holding)) {
            ++unencodable;
          }
        }
        sleep_until_ns(w.reply_ns);
        // A loaded machine wakes us late: the reply (not the sample) is late, which moves the
        // daemon's transaction midpoint by half of it. Counted for the summary.
        if (monotonic_ns() - w.reply_ns > 500'000) ++late_replies;
      }
      // Logged before the reply: a test that SIGKILLs us right after the client saw the
      // acknowledgement must find that write in the log.
      if (writes_command(query.data())) log_command(t, commanded_in(query.data(), header), "");
      modbus_reply(ctx, query.data(), rc, mb);
      if (o.wallclock && writes_command(query.data())) {
        plant.write_voltage(decode_command(map.command, mb->tab_registers));  // from t_event on
        ++k;
      }
      if (writes_command(query.data()) && o.lockstep) {
        step();  // the reply went out first: the client is not kept waiting
      }
    }
    if (!tcp) modbus_set_socket(ctx, rtu_fd);
  }

  std::printf(
      "scp-simdaq: stopped after %.3f s: %llu requests, %llu unanswered, %llu exception replies, "
      "%llu samples that did not fit their register type, %llu replies sent late, %llu "
      "watchdog trips, %llu replies sent > 0.5 ms after the emulated line would have delivered "
      "them\n",
      std::chrono::duration<double>(Clock::now() - start).count(),
      static_cast<unsigned long long>(requests), static_cast<unsigned long long>(dropped),
      static_cast<unsigned long long>(exceptions), static_cast<unsigned long long>(unencodable),
      static_cast<unsigned long long>(late), static_cast<unsigned long long>(watchdog_trips),
      static_cast<unsigned long long>(late_replies));
  std::fflush(stdout);
  if (log != nullptr) std::fclose(log);
  plant.close();
  for (const int c : clients) ::close(c);
  if (listen_fd >= 0) ::close(listen_fd);
  if (tcp) {
    modbus_free(ctx);
  } else {
    modbus_close(ctx);
    modbus_free(ctx);
  }
  modbus_mapping_free(mb);
  return 0;
}

}  // namespace scp::drivers::simdaq

#include "drivers/simdaq/simdaq_server.hpp"

#include <arpa/inet.h>
#include <modbus/modbus.h>
#include <netinet/in.h>
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
#include <set>
#include <vector>

#include "drivers/modbus/register_codec.hpp"
#include "drivers/modbus/register_map.hpp"
#include "drivers/sim/sim_driver.hpp"

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

using Clock = std::chrono::steady_clock;

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
  const int n_holding = table_size(map, Table::holding);
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

  std::set<int> clients;
  std::vector<std::uint8_t> query(MODBUS_MAX_ADU_LENGTH);
  const auto start = Clock::now();
  const auto period =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.period_s));
  auto next = start + period;
  std::int64_t k = 0;
  std::uint64_t requests = 0, dropped = 0, exceptions = 0, unencodable = 0;
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
  const int command_end = map.command.address + modbus::register_count(map.command.type);
  // Whether a request (function 6 or 16) wrote into the command register.
  const auto writes_command = [&](const std::uint8_t* q) {
    const int h = modbus_get_header_length(ctx);
    const int function = q[h];
    if (function != 0x06 && function != 0x10) return false;
    const int first = (q[h + 1] << 8) | q[h + 2];
    const int count = function == 0x06 ? 1 : ((q[h + 3] << 8) | q[h + 4]);
    return first < command_end && first + count > map.command.address;
  };

  while (!stop.load()) {
    auto now = Clock::now();
    const double elapsed = std::chrono::duration<double>(now - start).count();
    if (o.duration_s > 0 && elapsed >= o.duration_s) break;
    // The plant advances by whole periods of wall-clock time; far behind (a suspended process)
    // it catches up at most one second and then resynchronizes instead of spinning.
    int steps = 0;
    while (!o.lockstep && now >= next && steps < static_cast<int>(1.0 / o.period_s) + 1) {
      step();
      next += period;
      ++steps;
    }
    if (now >= next) next = now + period;
    // Lock-step: no deadline, only a bound so that Ctrl-C and --duration are seen.
    if (o.lockstep) next = now + std::chrono::milliseconds(100);

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
    if (ready <= 0) continue;  // timeout or EINTR (Ctrl-C)

    if (tcp && FD_ISSET(listen_fd, &fds)) {
      const int c = accept(listen_fd, nullptr, nullptr);
      if (c >= 0) clients.insert(c);
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
      if (in_window(t, o.fault_after_s, o.fault_duration_s)) {
        ++dropped;  // a dead slave: the request is read and never answered
        continue;
      }
      if (in_window(t, o.exception_after_s, o.fault_duration_s)) {
        ++exceptions;
        modbus_reply_exception(ctx, query.data(), static_cast<unsigned>(o.exception_code));
        continue;
      }
      modbus_reply(ctx, query.data(), rc, mb);
      if (writes_command(query.data())) {
        if (log != nullptr) {
          std::fprintf(log, "%lld,%.6f,%.9g\n", static_cast<long long>(k), t,
                       decode_command(map.command, mb->tab_registers));
        }
        if (o.lockstep) step();  // the reply went out first: the client is not kept waiting
      }
    }
    if (!tcp) modbus_set_socket(ctx, rtu_fd);
  }

  std::printf(
      "scp-simdaq: stopped after %.3f s: %llu requests, %llu unanswered, %llu exception replies, "
      "%llu samples that did not fit their register type\n",
      std::chrono::duration<double>(Clock::now() - start).count(),
      static_cast<unsigned long long>(requests), static_cast<unsigned long long>(dropped),
      static_cast<unsigned long long>(exceptions), static_cast<unsigned long long>(unencodable));
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

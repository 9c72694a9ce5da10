// scp-simdaq: the simulated SCP actuator served as a Modbus TCP server, a Modbus RTU slave or a
// CAN node, with the register map of a daemon config file. See docs/simdaq.md.

#include <sched.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <exception>
#include <string>

#include "daemon/config/binder.hpp"
#include "daemon/config/daemon_config.hpp"
#include "daemon/programs/cli/conventions.hpp"
#include "drivers/can/can_settings.hpp"
#include "drivers/can/can_sim_node.hpp"
#include "drivers/driver.hpp"
#include "tools/simdaq/simdaq_server.hpp"

namespace {

std::atomic<bool> g_stop{false};

extern "C" void on_signal(int) {
  g_stop.store(true);
}

void install_signal_handlers() {
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = 0;  // no SA_RESTART: select() returns EINTR and the loop sees the flag
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  std::signal(SIGPIPE, SIG_IGN);  // a client vanishing mid-reply is not a reason to die
}

// A DAQ answers in bounded time; an ordinary process on a loaded machine does not. With
// --priority the simulated DAQ is scheduled like the daemon's loop, so late replies seen by the
// daemon come from the transport, not from scp-simdaq waiting for a CPU.
void set_realtime_priority(int priority) {
  if (priority <= 0) return;
  sched_param param{};
  param.sched_priority = priority;
  if (sched_setscheduler(0, SCHED_FIFO, &param) != 0) {
    std::fprintf(stderr,
                 "scp-simdaq: warning: SCHED_FIFO priority %d refused (%s); running with ordinary "
                 "scheduling. Run as root or grant CAP_SYS_NICE.\n",
                 priority, std::strerror(errno));
  }
}

scp::cli::ProgramInfo program_info() {
  scp::cli::ProgramInfo info;
  info.name = "scp-simdaq";
  info.section = 1;
  info.summary = "a simulated SCP actuator behind a Modbus TCP/RTU or CAN DAQ";
  info.synopsis = {
      "--config FILE [--transport tcp|rtu|can] [--listen HOST:PORT] [--device DEV] "
      "[OPTIONS]",
      "--version | --help"};
  info.description = {
      "scp-simdaq serves the simulated super-coiled polymer actuator of a scp-estimatord "
      "configuration (driver.sim: plant, noise, drift, faults) behind the register map of its "
      "driver.modbus section, as a Modbus TCP server or RTU slave, or as a CAN node with the "
      "frames of driver.can. scp-estimatord(8) then talks to it exactly as to the bench, so a "
      "configuration can be rehearsed without hardware.",
      "It reads the configuration with the daemon's own loader, so a file it accepts is one the "
      "daemon accepts. /usr/share/doc/scp-estimator/simdaq.md describes the set-ups (TCP, a socat "
      "pty pair for RTU, vcan for CAN) and the fault options."};
  info.exit_codes = {
      {"0", "stopped by SIGINT/SIGTERM or after --duration"},
      {"1", "the Modbus server or CAN node failed while serving (message on stderr)"},
      {"2", "the configuration or the device could not be used (message on stderr)"},
      {"64", "usage error (unknown or misused option)"}};
  info.examples = {
      {"scp-simdaq --config /usr/share/doc/scp-estimator/examples/modbus-tcp.yaml --listen "
       "127.0.0.1:1502",
       "serve the Modbus TCP example's register map on port 1502"},
      {"scp-simdaq --config can.yaml --device vcan0", "act as the CAN node of can.yaml on vcan0"}};
  info.see_also = {"scp-estimatord(8)", "scp-estimator.yaml(5)", "scp-estimatorctl(1)"};
  return info;
}

// The command line, as parsed.
struct Options {
  std::string config_path;
  std::string listen;
  std::string device;
  std::string transport;
  double period = 0.0;
  std::string can_fault = "silent";
  int priority = 0;
  scp::drivers::simdaq::SimDaqOptions sim_daq;
};

void declare_options(CLI::App& app, Options& o) {
  app.add_option("--config", o.config_path, "daemon config file whose driver.modbus map is served")
      ->type_name("FILE")
      ->required();
  app.add_option("--listen", o.listen,
                 "TCP HOST:PORT to listen on (default: driver.modbus.tcp; port "
                 "0 picks a free one, printed on stdout)");
  app.add_option("--device", o.device,
                 "RTU: serial device (e.g. a socat pty); CAN: interface (e.g. vcan0)");
  app.add_option("--transport", o.transport, "tcp|rtu|can (default: driver.modbus.transport)")
      ->check(CLI::IsMember({"tcp", "rtu", "can"}));
  app.add_option("--period", o.period, "plant step in s (default: loop.period_s of the config)")
      ->check(CLI::Range(1e-4, 1.0));
  app.add_option("--fault-after", o.sim_daq.fault_after_s,
                 "after S seconds, read requests and never answer (a dead slave)");
  app.add_option("--exception-after", o.sim_daq.exception_after_s,
                 "after S seconds, answer every request with an exception");
  app.add_option("--exception-code", o.sim_daq.exception_code,
                 "exception code for --exception-after (default 4, server device failure)")
      ->check(CLI::Range(1, 11));
  app.add_option("--fault-duration", o.sim_daq.fault_duration_s,
                 "length of the --fault-after / --exception-after window in s (default: for ever)");
  app.add_flag("--exception-reads-only", o.sim_daq.exception_reads_only,
               "--exception-after answers reads with exceptions but still accepts writes (a "
               "failed input module)");
  app.add_option("--late-every", o.sim_daq.late_every,
                 "answer every Nth request late, after --late-factor x the config's "
                 "driver.modbus.response_timeout (0 = never)")
      ->check(CLI::Range(0, 1000000));
  app.add_option("--late-factor", o.sim_daq.late_factor,
                 "how late --late-every replies come, in response timeouts (default 1.5)")
      ->check(CLI::Range(1.0, 100.0));
  app.add_option("--watchdog-timeout", o.sim_daq.watchdog_timeout_s,
                 "the DAQ's communication watchdog: unfed for S seconds, the output falls to 0 V "
                 "(0 = off). CAN: fed by the driver.can.heartbeat frame when enabled, else by "
                 "the command frame")
      ->check(CLI::Range(0.0, 3600.0));
  app.add_option("--watchdog-register", o.sim_daq.watchdog_register,
                 "holding register whose writes feed the watchdog (default: any request does)")
      ->check(CLI::Range(-1, 65535));
  app.add_option("--can-fault", o.can_fault,
                 "CAN: what --fault-after does: silent (no sensor frames), bus_off (bus-off "
                 "error frame, restarted at the end of the window), error_frames (one "
                 "controller-warning error frame per period)")
      ->check(CLI::IsMember({"silent", "bus_off", "error_frames"}));
  app.add_flag("--lockstep", o.sim_daq.lockstep,
               "advance the plant one period per command write (offline runs), not per period "
               "of wall time");
  app.add_flag("--wallclock", o.sim_daq.wallclock,
               "integrate the plant in continuous wall-clock time: sample it when a read request "
               "arrives, switch its voltage when a command write arrives (not on a period grid)");
  app.add_flag("--wire", o.sim_daq.wire,
               "with --wallclock: put an emulated RTU line (baud, parity, stop bits of "
               "driver.modbus.rtu) between the daemon and the plant, whatever the transport");
  app.add_option("--wire-jitter", o.sim_daq.wire_jitter_s,
                 "with --wire: delay each frame by a uniform random 0..S s more (default 0)")
      ->check(CLI::Range(0.0, 0.1));
  app.add_option("--wire-gap", o.sim_daq.wire_gap_s,
                 "with --wire: inter-frame silence in s (default 3.5 characters)")
      ->check(CLI::Range(0.0, 0.1));
  app.add_option("--command-log", o.sim_daq.command_log,
                 "write one line step,wall_s,volts per voltage command received");
  app.add_option("--priority", o.priority,
                 "SCHED_FIFO priority 1-99 for scp-simdaq (default 0: ordinary scheduling)")
      ->check(CLI::Range(0, 99));
  app.add_option("--duration", o.sim_daq.duration_s, "exit after S seconds (0 = until Ctrl-C)");
}

// Usage mistakes CLI11 cannot see; the message, or "" when the options go together.
std::string usage_problem(const Options& o) {
  if (o.sim_daq.lockstep && o.sim_daq.wallclock)
    return "--lockstep and --wallclock exclude each other";
  if (o.sim_daq.wire && !o.sim_daq.wallclock) {
    return "--wire needs --wallclock (a stepped plant has no instants)";
  }
  return {};
}

int serve_can(const scp::config::DaemonConfig& cfg, const Options& o) {
  namespace can = scp::drivers::can;
  const auto& options = o.sim_daq;
  if (options.wallclock) {
    std::fprintf(stderr,
                 "scp-simdaq: --wallclock and --wire are for Modbus; the CAN node "
                 "sends its frames on its own period\n");
    return 2;
  }
  can::CanSettings settings = cfg.driver.can;
  if (!o.device.empty()) settings.interface = o.device;
  can::CanNodeOptions node;
  node.period_s = options.period_s;
  node.fd = can::inherited_fd(settings.interface);  // --device fd:N: an inherited socket
  node.lockstep = options.lockstep;
  node.command_log = options.command_log;
  node.fault_after_s = options.fault_after_s;
  node.fault_duration_s = options.fault_duration_s;
  node.fault = o.can_fault == "bus_off"        ? can::CanNodeFault::bus_off
               : o.can_fault == "error_frames" ? can::CanNodeFault::error_frames
                                               : can::CanNodeFault::silent;
  node.duration_s = options.duration_s;
  node.watchdog_timeout_s = options.watchdog_timeout_s;
  return can::run_can_sim_node(settings, options.sim, node, g_stop);
}

int run(Options o) {
  using scp::drivers::modbus::Transport;
  // The daemon's own loader: the same checks, the plant of driver.sim (noise, faults, drift)
  // and the period of loop.period_s, so simdaq serves exactly what the daemon will expect.
  const scp::config::DaemonConfig cfg = scp::config::load_config_file(o.config_path);
  auto& options = o.sim_daq;
  options.map = cfg.driver.modbus;
  options.sim = cfg.driver.sim;
  options.period_s = o.period > 0 ? o.period : cfg.loop.period_s;
  if (o.transport.empty() && cfg.driver.type == scp::config::DriverType::can) o.transport = "can";
  if (!o.transport.empty()) {
    options.map.transport = o.transport == "rtu" ? Transport::rtu : Transport::tcp;
  }
  if (!o.listen.empty()) {
    const auto colon = o.listen.rfind(':');
    if (colon == std::string::npos) {
      std::fprintf(stderr, "scp-simdaq: --listen wants HOST:PORT, e.g. 127.0.0.1:1502\n");
      return scp::cli::kExitUsage;
    }
    options.map.host = o.listen.substr(0, colon);
    options.map.port = std::stoi(o.listen.substr(colon + 1));
  }
  if (!o.device.empty()) options.map.device = o.device;
  install_signal_handlers();
  set_realtime_priority(o.priority);
  if (o.transport == "can") return serve_can(cfg, o);
  return scp::drivers::simdaq::serve_modbus(options, g_stop);
}

}  // namespace

int main(int argc, char** argv) {
  const scp::cli::ProgramInfo info = program_info();
  CLI::App app{"scp-simdaq: a simulated SCP actuator behind a Modbus TCP/RTU (or CAN) DAQ"};
  scp::cli::prepare(app, info);
  Options options;
  declare_options(app, options);
  if (const auto exit_code = scp::cli::parse(app, argc, argv, info)) return *exit_code;
  if (const std::string problem = usage_problem(options); !problem.empty()) {
    std::fprintf(stderr, "scp-simdaq: %s\n", problem.c_str());
    return scp::cli::kExitUsage;
  }
  try {
    return run(std::move(options));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "scp-simdaq: %s\n", e.what());
    return 2;
  }
}

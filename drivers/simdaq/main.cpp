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
#include "drivers/driver.hpp"
#include "drivers/simdaq/simdaq_server.hpp"

#if defined(SCP_SIMDAQ_WITH_CAN)
#include "drivers/can/can_settings.hpp"
#include "drivers/can/can_sim_node.hpp"
#endif

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

}  // namespace

int main(int argc, char** argv) {
  using scp::drivers::modbus::Transport;
  CLI::App app{"scp-simdaq: a simulated SCP actuator behind a Modbus TCP/RTU (or CAN) DAQ"};
  std::string config_path;
  std::string listen;
  std::string device;
  std::string transport;
  double period = 0.0;
  scp::drivers::simdaq::SimDaqOptions options;
  app.add_option("--config", config_path, "daemon config file whose driver.modbus map is served")
      ->required();
  app.add_option("--listen", listen,
                 "TCP HOST:PORT to listen on (default: driver.modbus.tcp; port "
                 "0 picks a free one, printed on stdout)");
  app.add_option("--device", device,
                 "RTU: serial device (e.g. a socat pty); CAN: interface (e.g. vcan0)");
  app.add_option("--transport", transport, "tcp|rtu|can (default: driver.modbus.transport)")
      ->check(CLI::IsMember({"tcp", "rtu", "can"}));
  app.add_option("--period", period, "plant step in s (default: loop.period_s of the config)")
      ->check(CLI::Range(1e-4, 1.0));
  app.add_option("--fault-after", options.fault_after_s,
                 "after S seconds, read requests and never answer (a dead slave)");
  app.add_option("--exception-after", options.exception_after_s,
                 "after S seconds, answer every request with an exception");
  app.add_option("--exception-code", options.exception_code,
                 "exception code for --exception-after (default 4, server device failure)")
      ->check(CLI::Range(1, 11));
  app.add_option("--fault-duration", options.fault_duration_s,
                 "length of the --fault-after / --exception-after window in s (default: for ever)");
  std::string can_fault = "silent";
  app.add_option("--can-fault", can_fault,
                 "CAN: what --fault-after does: silent (no sensor frames), bus_off (bus-off "
                 "error frame, restarted at the end of the window), error_frames (one "
                 "controller-warning error frame per period)")
      ->check(CLI::IsMember({"silent", "bus_off", "error_frames"}));
  app.add_flag("--lockstep", options.lockstep,
               "advance the plant one period per command write (offline runs), not per period "
               "of wall time");
  app.add_option("--command-log", options.command_log,
                 "write one line step,wall_s,volts per voltage command received");
  int priority = 0;
  app.add_option("--priority", priority,
                 "SCHED_FIFO priority 1-99 for scp-simdaq (default 0: ordinary scheduling)")
      ->check(CLI::Range(0, 99));
  app.add_option("--duration", options.duration_s, "exit after S seconds (0 = until Ctrl-C)");
  CLI11_PARSE(app, argc, argv);

  try {
    // The daemon's own loader: the same checks, the plant of driver.sim (noise, faults, drift)
    // and the period of loop.period_s, so simdaq serves exactly what the daemon will expect.
    const scp::config::DaemonConfig cfg = scp::config::load_config_file(config_path);
    options.map = cfg.driver.modbus;
    options.sim = cfg.driver.sim;
    options.period_s = cfg.loop.period_s;
    if (transport.empty() && cfg.driver.type == "can") transport = "can";
    if (period > 0) options.period_s = period;

    if (!transport.empty()) {
      options.map.transport = transport == "rtu" ? Transport::rtu : Transport::tcp;
    }
    if (!listen.empty()) {
      const auto colon = listen.rfind(':');
      if (colon == std::string::npos) {
        std::fprintf(stderr, "scp-simdaq: --listen wants HOST:PORT, e.g. 127.0.0.1:1502\n");
        return 2;
      }
      options.map.host = listen.substr(0, colon);
      options.map.port = std::stoi(listen.substr(colon + 1));
    }
    if (!device.empty()) options.map.device = device;
    install_signal_handlers();
    set_realtime_priority(priority);

    if (transport == "can") {
#if defined(SCP_SIMDAQ_WITH_CAN)
      namespace can = scp::drivers::can;
      can::CanSettings settings = cfg.driver.can;
      if (!device.empty()) settings.interface = device;
      can::CanNodeOptions node;
      node.period_s = options.period_s;
      node.fd = can::inherited_fd(settings.interface);  // --device fd:N: an inherited socket
      node.lockstep = options.lockstep;
      node.command_log = options.command_log;
      node.fault_after_s = options.fault_after_s;
      node.fault_duration_s = options.fault_duration_s;
      node.fault = can_fault == "bus_off"        ? can::CanNodeFault::bus_off
                   : can_fault == "error_frames" ? can::CanNodeFault::error_frames
                                                 : can::CanNodeFault::silent;
      node.duration_s = options.duration_s;
      return can::run_can_sim_node(settings, options.sim, node, g_stop);
#else
      std::fprintf(stderr, "scp-simdaq: built without the CAN simulated node (drivers/can)\n");
      return 2;
#endif
    }
    return scp::drivers::simdaq::serve_modbus(options, g_stop);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "scp-simdaq: %s\n", e.what());
    return 2;
  }
}

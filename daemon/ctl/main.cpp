// scp-estimatorctl: query and command scp-estimatord over its socket (docs/protocol.md).
//
// Exit codes: 0 success, 1 the daemon refused (ERROR, or ACK with ok:false), 2 the daemon could
// not be reached or did not answer in time.

#include <CLI/CLI.hpp>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <string>

#include "daemon/ctl/connection.hpp"
#include "daemon/ctl/format.hpp"

namespace {

using nlohmann::json;
using scp::daemon::ctl::Connection;
using scp::daemon::ctl::CtlError;
using scp::daemon::ctl::kExitRefused;
using scp::daemon::ctl::kExitUnreachable;

constexpr const char* kDefaultSocket = "/run/scp-estimator/scp-estimator.sock";

std::string default_socket() {
  const char* env = std::getenv("SCP_ESTIMATOR_SOCKET");
  return env != nullptr && *env != '\0' ? env : kDefaultSocket;
}

int print_ack(const json& reply, bool raw) {
  if (raw) {
    std::cout << reply.dump() << '\n';
  } else {
    std::cout << reply.value("request", "?") << ": "
              << (reply.value("ok", false) ? "ok" : "refused");
    if (reply.contains("message")) std::cout << " (" << reply.value("message", "") << ")";
    std::cout << '\n';
  }
  if (reply.value("class", "") != "ACK")
    throw CtlError(kExitUnreachable, "expected an ACK, got " + reply.dump());
  return reply.value("ok", false) ? 0 : kExitRefused;
}

int watch(Connection& connection, double rate_hz, long count, bool raw, double timeout_s) {
  const json reply = connection.exchange({{"request", "watch"}, {"rate_hz", rate_hz}});
  if (reply.value("class", "") != "WATCH")
    throw CtlError(kExitUnreachable, "expected a WATCH reply, got " + reply.dump());
  // Wait at least a few periods: a slow stream is not a dead daemon.
  const double wait_s = std::max(timeout_s, 3.0 / rate_hz);
  for (long received = 0; count <= 0 || received < count;) {
    const json object = connection.read_object(wait_s);
    const std::string cls = object.value("class", "");
    if (cls == "ERROR")
      throw CtlError(kExitRefused, "scp-estimatord: " + object.value("message", "(no message)"));
    if (cls != "ESTIMATE") continue;
    std::cout << (raw ? object.dump() + '\n' : scp::daemon::ctl::format_estimate_line(object))
              << std::flush;
    ++received;
  }
  connection.send({{"request", "watch"}, {"enable", false}});
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Query and command scp-estimatord over its Unix socket (docs/protocol.md)."};
  app.require_subcommand(1);
  std::string socket_path = default_socket();
  bool raw = false;
  double timeout_s = 5.0;
  app.add_option(
      "--socket", socket_path,
      "daemon socket (default: $SCP_ESTIMATOR_SOCKET or " + std::string(kDefaultSocket) + ")");
  app.add_flag("--json", raw, "print the daemon's JSON objects unchanged");
  app.add_option("--timeout", timeout_s, "seconds to wait for the daemon")
      ->check(CLI::Range(0.1, 3600.0));

  auto* status = app.add_subcommand("status", "daemon state, fault reason, loop statistics");
  auto* get = app.add_subcommand("get", "current parameter estimate with its uncertainty");
  auto* watch_cmd = app.add_subcommand("watch", "stream estimates");
  double rate_hz = 1.0;
  long count = 0;
  watch_cmd->add_option("--rate", rate_hz, "estimates per second")->check(CLI::Range(0.1, 1000.0));
  watch_cmd->add_option("--count", count, "stop after N estimates (0 = until interrupted)")
      ->check(CLI::NonNegativeNumber);
  auto* reset = app.add_subcommand("reset", "restart the estimator from its initial values");
  auto* excitation = app.add_subcommand("excitation", "switch the excitation signal on or off");
  std::string on_off;
  excitation->add_option("state", on_off, "on or off")
      ->required()
      ->check(CLI::IsMember({"on", "off"}));
  auto* clear_fault =
      app.add_subcommand("clear-fault", "leave the fault state if its cause is gone");

  CLI11_PARSE(app, argc, argv);

  try {
    Connection connection(socket_path, timeout_s);
    if (status->parsed()) {
      const json reply = connection.exchange({{"request", "status"}});
      std::cout << (raw ? reply.dump() + '\n' : scp::daemon::ctl::format_status(reply));
      return 0;
    }
    if (get->parsed()) {
      const json reply = connection.exchange({{"request", "estimate"}});
      std::cout << (raw ? reply.dump() + '\n' : scp::daemon::ctl::format_estimate(reply));
      return 0;
    }
    if (watch_cmd->parsed()) return watch(connection, rate_hz, count, raw, timeout_s);
    if (reset->parsed()) return print_ack(connection.exchange({{"request", "reset"}}), raw);
    if (excitation->parsed())
      return print_ack(connection.exchange({{"request", "excitation"}, {"enable", on_off == "on"}}),
                       raw);
    if (clear_fault->parsed())
      return print_ack(connection.exchange({{"request", "clear-fault"}}), raw);
  } catch (const CtlError& error) {
    std::cerr << "scp-estimatorctl: " << error.what() << '\n';
    return error.exit_code();
  } catch (const std::exception& error) {
    std::cerr << "scp-estimatorctl: unexpected reply from the daemon: " << error.what() << '\n';
    return kExitUnreachable;
  }
  return 0;
}

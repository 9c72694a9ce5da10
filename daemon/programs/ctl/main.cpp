// scp-estimatorctl: query and command scp-estimatord over its socket (docs/protocol.md).
//
// Exit codes: 0 success, 1 the daemon refused (ERROR, or ACK with ok:false), 2 the daemon could
// not be reached or did not answer in time, 3 `wait` timed out, 64 usage error.

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <string>
#include <thread>

#include "daemon/outputs/metrics/exposition.hpp"
#include "daemon/programs/cli/conventions.hpp"
#include "daemon/programs/cli/instance_names.hpp"
#include "daemon/programs/ctl/connection.hpp"
#include "daemon/programs/ctl/format.hpp"

namespace {

using nlohmann::json;
using scp::daemon::ctl::Connection;
using scp::daemon::ctl::CtlError;
using scp::daemon::ctl::kExitNotReached;
using scp::daemon::ctl::kExitRefused;
using scp::daemon::ctl::kExitUnreachable;

constexpr const char* kDefaultSocket = "/run/scp-estimator/scp-estimator.sock";

std::string default_socket() {
  const char* env = std::getenv("SCP_ESTIMATOR_SOCKET");
  return env != nullptr && *env != '\0' ? env : kDefaultSocket;
}

scp::cli::ProgramInfo program_info() {
  scp::cli::ProgramInfo info;
  info.name = "scp-estimatorctl";
  info.section = 1;
  info.summary = "query and command the SCP actuator estimator daemon";
  info.synopsis = {
      "[--socket PATH | --instance NAME] [--json] [--timeout S] COMMAND [COMMAND OPTIONS]",
      "--version | --help"};
  info.description = {
      "scp-estimatorctl talks to scp-estimatord(8) over its Unix socket, speaking the JSON "
      "protocol described in /usr/share/doc/scp-estimator/protocol.md. status and get print "
      "tables (with --json, the daemon's objects unchanged, one per line), watch one line per "
      "estimate, and wait blocks until the daemon is running or its estimate has converged, so "
      "that scripts can wait for health like chronyc waitsync.",
      "health prints whether the actuator is still the one its baseline describes: ok, drift or "
      "changed (with the parameter, its change with σ and the onset), or blind without a "
      "baseline; baseline save stores the current refined estimate as the healthy actuator "
      "(refused until the refinement has converged), baseline show prints it, baseline clear "
      "removes it, health ack acknowledges a latched drift or change "
      "(/usr/share/doc/scp-estimator/health.md).",
      "Reading (status, get, watch, wait, health, baseline show) is open to anyone who can "
      "connect to the socket. reset, excitation, clear-fault, health ack, baseline save and "
      "baseline clear change the daemon's state and need root, the daemon's user or the group "
      "named by socket.group in scp-estimator.yaml(5); they are audited in the journal."};
  info.exit_codes = {
      {"0", "success (wait: the state was reached)"},
      {"1",
       "the daemon refused the request (ERROR, or an ACK with ok false); its message is "
       "printed"},
      {"2",
       "the daemon could not be reached, did not answer within --timeout, or speaks another "
       "protocol major version"},
      {"3", "wait: the state was not reached within wait's --timeout"},
      {"64", "usage error (unknown command or option, bad value)"}};
  info.environment = {{"SCP_ESTIMATOR_SOCKET", "socket used when --socket is not given"}};
  info.files = {{kDefaultSocket, "the daemon's socket (socket.path)"}};
  info.examples = {
      {"scp-estimatorctl get", "print θ̂ with its standard deviation"},
      {"scp-estimatorctl watch --rate 10 --json | jq .theta_hat", "stream estimates to jq"},
      {"scp-estimatorctl metrics | promtool check metrics",
       "print the Prometheus metrics and lint them"},
      {"scp-estimatorctl wait --state converged --timeout 600 && scp-estimatorctl get --json",
       "wait up to ten minutes for convergence, then save the estimate"},
      {"scp-estimatorctl baseline save", "this is the healthy actuator: tell me when it changes"},
      {"scp-estimatorctl health", "has it changed, how much, since when"}};
  info.see_also = {"scp-estimatord(8)", "scp-estimator.yaml(5)", "scp-simdaq(1)"};
  info.completion_words = {{"excitation", "on off"},
                           {"wait", "running converged"},
                           {"health", "ack"},
                           {"baseline", "save show clear"}};
  return info;
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

bool all_converged(const json& estimate) {
  const auto it = estimate.find("converged");
  if (it == estimate.end() || !it->is_object() || it->empty()) return false;
  for (const auto& block : *it)
    if (!block.is_boolean() || !block.get<bool>()) return false;
  return true;
}

// Polls STATUS (and ESTIMATE for `converged`) until the state is reached or `limit_s` passes
// (0 = no limit), like chronyc waitsync.
int wait_for(Connection& connection, const std::string& target, double limit_s, bool raw) {
  using Clock = std::chrono::steady_clock;
  const auto start = Clock::now();
  std::string last = "unknown";
  for (;;) {
    const json status = connection.exchange({{"request", "status"}});
    last = status.value("state", "unknown");
    if (status.contains("fault_reason")) {
      last += " (";
      last += status.value("fault_reason", "");
      last += ')';
    } else if (status.contains("waiting_for_device")) {
      last += " (waiting for the device: ";
      last += status.value("waiting_for_device", "");
      last += ')';
    }
    bool reached = status.value("state", "") == "running";
    json estimate;
    if (reached && target == "converged") {
      estimate = connection.exchange({{"request", "estimate"}});
      reached = all_converged(estimate);
      if (!reached) last = "running, not converged";
    }
    if (reached) {
      if (raw) {
        std::cout << (target == "converged" ? estimate : status).dump() << '\n';
      } else {
        std::cout << target << '\n';
      }
      return 0;
    }
    const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();
    if (limit_s > 0 && elapsed >= limit_s) {
      std::fprintf(stderr, "scp-estimatorctl: not %s after %g s; state %s\n", target.c_str(),
                   limit_s, last.c_str());
      return kExitNotReached;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
}

// The command line, as parsed: the global options and each subcommand's.
struct Options {
  std::string socket_path = default_socket();
  std::string instance;
  bool raw = false;
  double timeout_s = 5.0;
  double rate_hz = 1.0;  // watch
  long count = 0;        // watch
  std::string target;    // wait
  double wait_limit_s = 0.0;
  std::string on_off;           // excitation
  std::string health_action;    // health: "" or ack
  std::string baseline_action;  // baseline: save, show or clear
};

struct Subcommands {
  CLI::App* status;
  CLI::App* get;
  CLI::App* watch;
  CLI::App* wait;
  CLI::App* metrics;
  CLI::App* reset;
  CLI::App* excitation;
  CLI::App* clear_fault;
  CLI::App* health;
  CLI::App* baseline;
};

void declare_options(CLI::App& app, Options& o) {
  app.add_option(
         "--socket", o.socket_path,
         "daemon socket (default: $SCP_ESTIMATOR_SOCKET or " + std::string(kDefaultSocket) + ")")
      ->type_name("PATH");
  app.add_option("--instance", o.instance,
                 "talk to instance NAME of scp-estimatord@.service (socket "
                 "/run/scp-estimator/NAME.sock)")
      ->type_name("NAME")
      ->excludes("--socket");
  app.add_flag("--json", o.raw, "print the daemon's JSON objects unchanged, one per line");
  app.add_option("--timeout", o.timeout_s,
                 "seconds to wait for each answer of the daemon (default 5)")
      ->type_name("S")
      ->check(CLI::Range(0.1, 3600.0));
}

Subcommands declare_subcommands(CLI::App& app, Options& o) {
  Subcommands c{};
  c.status = app.add_subcommand("status", "daemon state, fault reason, loop statistics");
  c.get = app.add_subcommand("get", "current parameter estimate with its uncertainty");
  c.watch = app.add_subcommand("watch", "stream estimates");
  c.watch->add_option("--rate", o.rate_hz, "estimates per second (default 1)")
      ->type_name("HZ")
      ->check(CLI::Range(0.1, 1000.0));
  c.watch->add_option("--count", o.count, "stop after N estimates (default 0: until interrupted)")
      ->type_name("N")
      ->check(CLI::NonNegativeNumber);
  c.wait = app.add_subcommand(
      "wait", "wait until the daemon is running, or running with every block converged");
  c.wait->add_option("--state", o.target, "running or converged")
      ->type_name("STATE")
      ->required()
      ->check(CLI::IsMember({"running", "converged"}));
  c.wait
      ->add_option("--timeout", o.wait_limit_s,
                   "give up after S seconds with exit status 3 (default 0: wait for ever)")
      ->type_name("S")
      ->check(CLI::Range(0.0, 1e9));
  c.metrics = app.add_subcommand(
      "metrics",
      "print STATUS and ESTIMATE in the Prometheus text format (what the daemon's "
      "metrics.textfile_directory receives)");
  c.reset = app.add_subcommand("reset", "restart the estimator from its initial values");
  c.excitation = app.add_subcommand("excitation", "switch the excitation signal on or off");
  c.excitation->add_option("state", o.on_off, "on or off")
      ->required()
      ->check(CLI::IsMember({"on", "off"}));
  c.clear_fault = app.add_subcommand("clear-fault", "leave the fault state if its cause is gone");
  c.health = app.add_subcommand(
      "health", "has the actuator changed since its baseline (ack: acknowledge a latched state)");
  c.health->add_option("action", o.health_action, "ack")->check(CLI::IsMember({"ack"}));
  c.baseline = app.add_subcommand(
      "baseline", "save the current refined estimate as the healthy actuator, show or clear it");
  c.baseline->add_option("action", o.baseline_action, "save, show or clear")
      ->required()
      ->check(CLI::IsMember({"save", "show", "clear"}));
  return c;
}

int print_reply(const json& reply, bool raw, std::string (*format)(const json&)) {
  std::cout << (raw ? reply.dump() + '\n' : format(reply));
  return 0;
}

int print_metrics(Connection& connection) {
  const json status = connection.exchange({{"request", "status"}});
  const json estimate = connection.exchange({{"request", "estimate"}});
  std::cout << scp::daemon::metrics::exposition(status, estimate,
                                                status.value("actuator", "scp-estimator"));
  return 0;
}

int health(Connection& connection, const Options& o) {
  if (o.health_action == "ack")
    return print_ack(connection.exchange({{"request", "health-ack"}}), o.raw);
  const json reply = connection.exchange({{"request", "health"}});
  if (reply.value("class", "") == "ERROR")
    throw CtlError(kExitRefused, "scp-estimatord: " + reply.value("message", "(no message)"));
  return print_reply(reply, o.raw, scp::daemon::ctl::format_health);
}

int baseline(Connection& connection, const Options& o) {
  const json reply = connection.exchange({{"request", "baseline-" + o.baseline_action}});
  if (reply.value("class", "") == "ERROR")
    throw CtlError(kExitRefused, "scp-estimatord: " + reply.value("message", "(no message)"));
  if (o.baseline_action != "show") return print_ack(reply, o.raw);
  return print_reply(reply, o.raw, scp::daemon::ctl::format_baseline);
}

int run(const Subcommands& c, const Options& o) {
  Connection connection(o.socket_path, o.timeout_s);
  using scp::daemon::ctl::format_estimate;
  using scp::daemon::ctl::format_status;
  if (c.status->parsed())
    return print_reply(connection.exchange({{"request", "status"}}), o.raw, format_status);
  if (c.get->parsed())
    return print_reply(connection.exchange({{"request", "estimate"}}), o.raw, format_estimate);
  if (c.metrics->parsed()) return print_metrics(connection);
  if (c.watch->parsed()) return watch(connection, o.rate_hz, o.count, o.raw, o.timeout_s);
  if (c.wait->parsed()) return wait_for(connection, o.target, o.wait_limit_s, o.raw);
  if (c.reset->parsed()) return print_ack(connection.exchange({{"request", "reset"}}), o.raw);
  if (c.excitation->parsed()) {
    return print_ack(connection.exchange({{"request", "excitation"}, {"enable", o.on_off == "on"}}),
                     o.raw);
  }
  if (c.clear_fault->parsed())
    return print_ack(connection.exchange({{"request", "clear-fault"}}), o.raw);
  if (c.health->parsed()) return health(connection, o);
  if (c.baseline->parsed()) return baseline(connection, o);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const scp::cli::ProgramInfo info = program_info();
  CLI::App app{"Query and command scp-estimatord over its Unix socket."};
  scp::cli::prepare(app, info);
  Options options;
  declare_options(app, options);
  const Subcommands commands = declare_subcommands(app, options);
  if (const auto exit_code = scp::cli::parse(app, argc, argv, info)) return *exit_code;
  if (!options.instance.empty()) {
    if (const std::string problem = scp::cli::instance_name_problem(options.instance);
        !problem.empty()) {
      std::cerr << "scp-estimatorctl: --" << problem << '\n';
      return scp::cli::kExitUsage;
    }
    options.socket_path = scp::cli::instance_socket(options.instance);
  }
  try {
    return run(commands, options);
  } catch (const CtlError& error) {
    std::cerr << "scp-estimatorctl: " << error.what() << '\n';
    return error.exit_code();
  } catch (const std::exception& error) {
    std::cerr << "scp-estimatorctl: unexpected reply from the daemon: " << error.what() << '\n';
    return kExitUnreachable;
  }
}

// scp-estimatord: the SCP estimator daemon (systemd service), and batch runs of the same loop.

#include <CLI/CLI.hpp>
#include <cstdio>
#include <iostream>

#include "daemon/batch/batch_run.hpp"
#include "daemon/config/binder.hpp"
#include "daemon/config/daemon_config.hpp"
#include "daemon/config/reference_man.hpp"
#include "daemon/config/startup_checks.hpp"
#include "daemon/programs/cli/conventions.hpp"
#include "daemon/service/instance.hpp"
#include "daemon/service/service.hpp"
#include "drivers/driver.hpp"

namespace {

constexpr const char* kDefaultConfig = "/etc/scp-estimator/scp-estimator.yaml";

scp::cli::ProgramInfo program_info() {
  scp::cli::ProgramInfo info;
  info.name = "scp-estimatord";
  info.section = 8;
  info.summary = "online parameter identification of super-coiled polymer actuators";
  info.synopsis = {
      "[--config FILE] [--instance NAME] [--log-level LEVEL]", "--check-config FILE",
      "--config FILE --offline [--duration S] [--record CSV] [--replay CSV] [--jobs N] [--json]",
      "--version | --help | --print-config-reference[=man]"};
  info.description = {
      "scp-estimatord reads a super-coiled polymer (SCP) actuator through a driver (a simulated "
      "actuator, a recorded CSV, a Modbus DAQ or a CAN device) in a fixed-period real-time loop, "
      "drives it with an identification voltage, and estimates θ = [b/m, α1/m, k/m, α2/m, λ/Cth, "
      "1/(R·Cth)] of m ẍ + b ẋ + α1 T̄ ẋ + k x = −α2 T̄, Cth dT̄/dt = −λ T̄ + V²/R with a "
      "filtered least-squares law. It publishes the estimate, its standard deviation and the "
      "loop's health on a Unix socket (scp-estimatorctl(1) is the client) and runs as the "
      "systemd service scp-estimatord.service.",
      "The output is 0 V at start until fresh readings arrive, on any fault, and on every "
      "shutdown path. A fault latches until scp-estimatorctl clear-fault.",
      "Log lines go to stderr. When stderr is the journal's stream (JOURNAL_STREAM names it, as "
      "systemd sets it) each line carries its priority, so that journalctl -p err shows the "
      "faults and -p notice the state changes, recoveries and every command an operator sent; "
      "in a terminal each line starts with its UTC time.",
      "With --offline the same loop runs as a batch, without sleeping, and prints a table and a "
      "JSON summary (with --json only the JSON line, so that stdout can be piped to jq).",
      "The configuration is described in scp-estimator.yaml(5); "
      "/usr/share/doc/scp-estimator/ holds the protocol, the numerics and the driver guides."};
  info.environment = {{"JOURNAL_STREAM",
                       "set by systemd to the device:inode of the journal stream; when it is "
                       "stderr, log lines get sd-daemon(3) priority prefixes instead of time "
                       "stamps"}};
  info.exit_codes = {{"0", "success; --check-config: the file is valid (warnings may be printed)"},
                     {"1", "a driver or run-time error (message on stderr)"},
                     {"64", "usage error (unknown or misused option)"},
                     {"69",
                      "the device did not answer within driver.start_timeout_s (EX_UNAVAILABLE): "
                      "check that the DAQ is powered and reachable, or raise the key (0 waits "
                      "without limit); systemd does not restart the service on it"},
                     {"78",
                      "configuration error (EX_CONFIG): the message names the file, line "
                      "and key; systemd does not restart the service on it"}};
  info.files = {{kDefaultConfig, "the configuration the service reads"},
                {"/run/scp-estimator/scp-estimator.sock", "the control socket (socket.path)"},
                {"/etc/scp-estimator/NAME.yaml, /run/scp-estimator/NAME.sock, "
                 "/var/lib/scp-estimator/NAME/",
                 "configuration, socket and state of instance NAME "
                 "(scp-estimatord@NAME.service, --instance NAME)"},
                {"/var/lib/scp-estimator/estimator.state",
                 "the checkpoint of θ̂ and its covariance (state.directory)"}};
  info.examples = {
      {"scp-estimatord --check-config /etc/scp-estimator/scp-estimator.yaml",
       "check the configuration before restarting the service"},
      {"scp-estimatord --config /usr/share/doc/scp-estimator/examples/paper.yaml --offline "
       "--duration 200 --json | jq .rel_error",
       "run the paper's experiment as a batch and print the relative errors"},
      {"scp-estimatord --config my-bench.yaml --offline --replay logged.csv",
       "estimate θ from data logged elsewhere"}};
  info.see_also = {"scp-estimatorctl(1)", "scp-estimator.yaml(5)", "scp-simdaq(1)",
                   "systemd.service(5)"};
  return info;
}

// Prints every finding; returns true when one would stop the daemon.
bool report(const scp::config::DaemonConfig& cfg,
            const std::vector<scp::config::Finding>& findings) {
  bool fatal = false;
  for (const auto& finding : findings) {
    const bool error = finding.severity == scp::config::Finding::Severity::error;
    fatal = fatal || error;
    std::fprintf(stderr, "scp-estimatord: %s: %s\n", error ? "error" : "warning",
                 scp::config::describe(cfg, finding).c_str());
  }
  return fatal;
}

// The command line, as parsed.
struct Options {
  std::string config_path = kDefaultConfig;
  std::string check_path;
  std::string reference;  // --print-config-reference: "markdown" or "man"
  bool offline = false;
  bool json_only = false;
  std::string log_level;
  std::string instance;
  scp::daemon::BatchOptions batch;  // its duration_s only when --duration is given
  double duration_s = scp::daemon::kDefaultBatchDuration;
  CLI::Option* duration = nullptr;
};

void declare_options(CLI::App& app, Options& o) {
  app.add_option(
         "-c,--config", o.config_path,
         "configuration file, scp-estimator.yaml(5) (default " + std::string(kDefaultConfig) + ")")
      ->type_name("FILE");
  app.add_option("--check-config", o.check_path,
                 "validate FILE and what it needs on this machine (group, files, directories), "
                 "warn about suspicious values, and exit (0 = the daemon can start with it)")
      ->type_name("FILE");
  app.add_flag("--print-config-reference{markdown}", o.reference,
               "print every configuration key and exit; =man prints scp-estimator.yaml(5)")
      ->check(CLI::IsMember({"markdown", "man"}));
  app.add_option("--log-level", o.log_level,
                 "log only messages at LEVEL or above, overriding the configuration's log_level "
                 "(trace, debug, info, warn, error)")
      ->type_name("LEVEL")
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error"}));
  app.add_option("--instance", o.instance,
                 "run as actuator NAME of several (scp-estimatord@NAME.service): socket "
                 "/run/scp-estimator/NAME.sock, state /var/lib/scp-estimator/NAME, and "
                 "actuator.name NAME unless the file sets it")
      ->type_name("NAME")
      ->check([](const std::string& name) { return scp::daemon::instance_name_problem(name); });
  auto* offline =
      app.add_flag("--offline", o.offline, "run the loop as a batch, without sleeping, and exit");
  o.duration = app.add_option("--duration", o.duration_s,
                              "loop time of a batch run, s (default: 200, or a replay's whole "
                              "file)")
                   ->type_name("S")
                   ->check(CLI::Range(0.0, 1e9))
                   ->needs(offline);
  app.add_option("--record", o.batch.record_path, "write every cycle of a batch run to this CSV")
      ->type_name("FILE")
      ->needs(offline);
  app.add_option("--replay", o.batch.replay_paths,
                 "feed these CSV files (t,x,xdot,T,V; .csv.gz read as they are), or a directory's "
                 "*.csv and *.csv.gz in name order (a rotated recording), instead of the driver")
      ->type_name("FILE|DIR ...")
      ->needs(offline);
  app.add_option("--jobs", o.batch.jobs,
                 "batch run: fits made at once on worker threads beside the loop (default 1: "
                 "inline between the loop's cycles)")
      ->type_name("N")
      ->check(CLI::Range(1U, 256U))
      ->needs(offline);
  app.add_flag("--json", o.json_only,
               "batch run: print only the JSON summary line on stdout (no table)")
      ->needs(offline);
}

// --check-config: exit 0 when the daemon can start with the file (warnings may be printed).
int check_config(const std::string& path) {
  const auto cfg = scp::config::load_config_file(path);
  if (report(cfg, scp::config::startup_findings(cfg))) {
    std::fprintf(stderr, "scp-estimatord: %s: fix the errors above before starting the daemon\n",
                 path.c_str());
    return scp::cli::kExitConfig;
  }
  std::cout << path << ": valid (driver " << scp::config::to_string(cfg.driver.type) << ", period "
            << cfg.loop.period_s << " s)\n";
  return 0;
}

int run_batch(const scp::config::DaemonConfig& cfg, const Options& o) {
  const auto summary = scp::daemon::run_batch(cfg, o.batch);
  if (!o.json_only) std::cout << scp::daemon::summary_table(summary);
  // The last line on stdout is one JSON object, for scripts.
  std::cout << summary.dump() << std::endl;
  return 0;
}

int run_service(const scp::config::DaemonConfig& cfg) {
  // Only the warnings: the errors are found by the start-up itself, with its own message.
  std::vector<scp::config::Finding> warnings;
  for (auto& finding : scp::config::startup_findings(cfg)) {
    if (finding.severity == scp::config::Finding::Severity::warning)
      warnings.push_back(std::move(finding));
  }
  report(cfg, warnings);
  return scp::daemon::run_service(cfg);
}

int run(const Options& o) {
  if (o.reference == "markdown") {
    std::cout << scp::config::config_reference_markdown();
    return 0;
  }
  if (o.reference == "man") {
    std::cout << scp::config::config_reference_man(scp::cli::version());
    return 0;
  }
  if (!o.check_path.empty()) return check_config(o.check_path);
  auto cfg = scp::config::load_config_file(o.config_path);
  if (!o.log_level.empty()) cfg.log_level = o.log_level;
  if (!o.instance.empty()) {
    for (const auto& warning : scp::daemon::apply_instance(cfg, o.instance))
      std::fprintf(stderr, "scp-estimatord: warning: %s\n", warning.c_str());
  }
  return o.offline ? run_batch(cfg, o) : run_service(cfg);
}

}  // namespace

int main(int argc, char** argv) {
  const scp::cli::ProgramInfo info = program_info();
  CLI::App app{"scp-estimatord: online identification of super-coiled polymer actuators"};
  scp::cli::prepare(app, info);
  Options options;
  declare_options(app, options);
  if (const auto exit_code = scp::cli::parse(app, argc, argv, info)) return *exit_code;
  if (options.duration->count() > 0) options.batch.duration_s = options.duration_s;
  try {
    return run(options);
  } catch (const scp::config::ConfigError& e) {
    std::fprintf(stderr, "scp-estimatord: configuration error: %s\n", e.what());
    return scp::cli::kExitConfig;  // EX_CONFIG: systemd shows it; Restart=on-failure stops on it
  } catch (const scp::drivers::DriverError& e) {
    std::fprintf(stderr, "scp-estimatord: driver: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "scp-estimatord: %s\n", e.what());
    return 1;
  }
}

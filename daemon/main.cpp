// scp-estimatord: the SCP estimator daemon (systemd service), and batch runs of the same loop.

#include <CLI/CLI.hpp>
#include <cstdio>
#include <iostream>

#include "daemon/batch_run.hpp"
#include "daemon/config/binder.hpp"
#include "daemon/config/daemon_config.hpp"
#include "daemon/service.hpp"
#include "drivers/driver.hpp"

int main(int argc, char** argv) {
  CLI::App app{"scp-estimatord: online identification of super-coiled polymer actuators"};
  std::string config_path = "/etc/scp-estimator/scp-estimator.yaml";
  std::string check_path;
  bool offline = false;
  bool reference = false;
  scp::daemon::BatchOptions batch;
  app.add_option("-c,--config", config_path, "configuration file (YAML)");
  app.add_option("--check-config", check_path, "validate FILE and exit (0 = valid)");
  app.add_flag("--print-config-reference", reference, "print every configuration key and exit");
  auto* offline_flag =
      app.add_flag("--offline", offline, "run the loop as a batch, without sleeping, and exit");
  app.add_option("--duration", batch.duration_s, "loop time of a batch run, s")
      ->check(CLI::Range(0.0, 1e9))
      ->needs(offline_flag);
  app.add_option("--record", batch.record_path, "write every cycle of a batch run to this CSV")
      ->needs(offline_flag);
  app.add_option("--replay", batch.replay_path,
                 "feed this CSV (t,x,xdot,T,V) instead of the driver")
      ->needs(offline_flag);
  CLI11_PARSE(app, argc, argv);

  try {
    if (reference) {
      std::cout << scp::config::config_reference_markdown();
      return 0;
    }
    if (!check_path.empty()) {
      const auto cfg = scp::config::load_config_file(check_path);
      std::cout << check_path << ": valid (driver " << cfg.driver.type << ", period "
                << cfg.loop.period_s << " s)\n";
      return 0;
    }
    auto cfg = scp::config::load_config_file(config_path);
    if (offline) {
      const auto summary = scp::daemon::run_batch(cfg, batch);
      std::cout << scp::daemon::summary_table(summary);
      // The last line on stdout is one JSON object, for scripts.
      std::cout << summary.dump() << std::endl;
      return 0;
    }
    return scp::daemon::run_service(cfg);
  } catch (const scp::config::ConfigError& e) {
    std::fprintf(stderr, "scp-estimatord: configuration error: %s\n", e.what());
    return 78;  // EX_CONFIG: systemd shows it, and Restart=on-failure will not loop on it
  } catch (const scp::drivers::DriverError& e) {
    std::fprintf(stderr, "scp-estimatord: driver: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "scp-estimatord: %s\n", e.what());
    return 1;
  }
}

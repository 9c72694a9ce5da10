#pragma once
// The daemon's whole configuration as plain structs, filled from YAML by declare_daemon_keys()
// (daemon_keys.cpp), where every key is declared exactly once with its default, range and doc.

#include <cstdint>
#include <string>
#include <vector>

#include "daemon/core/rt/rt_setup.hpp"
#include "drivers/can/can_settings.hpp"
#include "drivers/modbus/modbus_settings.hpp"
#include "drivers/sim/sim_settings.hpp"
#include "estimator/estimator.hpp"
#include "excitation/excitation_settings.hpp"

namespace scp::config {

class Binder;

struct LoopSettings {
  double period_s = 0.001;
  rt::RtSettings realtime;
  double overrun_warning_interval_s = 10.0;  // overrun warnings are rate-limited to one per this
};

struct ActuatorSettings {
  std::string name = "scp-estimator";  // identity: checkpoints, metrics label, STATUS
  double ambient_c = 25.0;             // T̄ = T − ambient
  double mass_kg = 0.0;  // 0 = unknown; with R, lets the daemon report b, k, α1, α2, λ, Cth
  double resistance_ohm = 0.0;  // 0 = unknown
};

struct VelocitySettings {
  std::string method = "central_difference";  // or "filtered"
  double bandwidth_hz = 20.0;
  double damping = 0.7071;
};

struct ReplaySettings {
  std::string file;
};

struct DriverSelection {
  std::string type = "sim";  // sim | replay | modbus | can
  // How long the service awaits a device that has not answered since start; 0 = without limit.
  double start_timeout_s = 0.0;
  drivers::sim::SimSettings sim;
  ReplaySettings replay;
  drivers::modbus::ModbusSettings modbus;
  drivers::can::CanSettings can;
  VelocitySettings velocity;
};

struct ExcitationConfig {
  bool enabled = true;  // at start; `excitation on|off` changes it at run time
  std::string profile = "paper";
  excitation::ExcitationSettings settings;
};

// Limits that never depend on the estimator: any one exceeded drives 0 V and FAULT.
struct SafetySettings {
  double voltage_max_v = 3.3;
  double temperature_max_c = 100.0;
  double temperature_min_c = -20.0;
  double position_abs_max_m = 0.05;
  double stale_timeout_s = 0.02;  // no fresh reading for this long is a fault
  double recover_after_s = 2.0;   // a driver fault clears after this long healthy; 0 = latch
  double stuck_timeout_s = 0.0;   // x and T bit-identical this long at non-zero output; 0 = off
};

struct SocketSettings {
  std::string path = "/run/scp-estimator/scp-estimator.sock";
  std::string group;
  unsigned mode = 0660;
  std::int64_t max_clients = 128;
  std::int64_t max_line_bytes = 4096;
  double idle_timeout_s = 300.0;
};

struct StateSettings {
  std::string directory = "/var/lib/scp-estimator";
  double checkpoint_interval_s = 60.0;
  bool warm_start = true;
  double warm_start_theta_max = 1e6;  // see daemon_keys.cpp
};

// The output-error refinement beside the paper's law (daemon/analysis/refine/, refine/fit.hpp): a
// worker thread below the loop fits θ to a sliding window of the samples the estimator was fed.
struct RefineSettings {
  bool enabled = true;
  double window_s = 300.0;      // the sliding window fitted (memory: see docs/configuration.md)
  double interval_s = 10.0;     // a fit every this much loop time
  double min_window_s = 30.0;   // no fit on a window shorter than this
  int max_iterations = 100;     // of the Gauss-Newton / Levenberg-Marquardt solver
  int hac_lags = 0;             // Newey-West lags of the covariance; 0 = automatic
  int covariance_batches = 20;  // the batch-means check on σ (refine/covariance.hpp); < 2 = off
  // A longer step between samples starts a new window; the model simulates through shorter ones
  // (missed periods, a failed read) with the voltage the DAC held.
  double max_gap_s = 0.2;
  // The link's timing: the voltage's delay relative to its recorded switch instants and the
  // samples' timing jitter, "estimate"d, taken as "recorded" (exact), or "auto": estimated unless
  // the driver is the simulated plant (exact instants); resolved by the loader into
  // estimate_link_timing.
  std::string link_timing = "auto";
  bool estimate_link_timing = false;
  double max_input_delay_s = 0.005;  // the delay is searched within ± this
};

// The Prometheus textfile the daemon writes (docs/metrics: node_exporter's textfile collector).
struct MetricsSettings {
  std::string textfile_directory;  // "" = no textfile
  double interval_s = 15.0;
};

// Recording in service mode: rotating CSV files written by a non-real-time thread.
struct RecordingSettings {
  std::string directory;              // "" = no recording
  double rotate_size_mib = 64.0;      // a new file after this many MiB (0 = no size limit)
  double rotate_interval_s = 3600.0;  // a new file after this long (0 = no time limit)
  std::int64_t keep_files = 168;      // older files are deleted (0 = keep all)
  std::string compress = "none";      // none | gzip: rotated files, by a thread below the recorder
};

struct DaemonConfig {
  std::string source;  // file it came from, for messages and `status`
  LoopSettings loop;
  ActuatorSettings actuator;
  DriverSelection driver;
  estimator::EstimatorConfig estimator;
  ExcitationConfig excitation;
  SafetySettings safety;
  SocketSettings socket;
  StateSettings state;
  RefineSettings refine;
  MetricsSettings metrics;
  RecordingSettings recording;
  std::string log_level = "info";
};

// Fills the settings that other keys decide: the estimator's sample period and input validity
// follow the loop and the safety limits, the simulated sensor reads the actuator's ambient, the
// paper's excitation profile, the refinement's link timing. The loader calls it after reading;
// a test that starts from the structs' defaults calls it to get what an empty file gives.
void derive_settings(DaemonConfig& config);

// Declares every key on `root` and fills `out`. Throws ConfigError naming key, line and range.
void declare_daemon_keys(Binder& root, DaemonConfig& out);

// Reads and validates a file (unknown keys are errors). Throws ConfigError.
DaemonConfig load_config_file(const std::string& path);
// The same from YAML text (tests, fuzzing). `name` appears in messages.
DaemonConfig load_config_text(const std::string& text, const std::string& name);
// Markdown reference of every key (scp-estimatord --print-config-reference).
std::string config_reference_markdown();

}  // namespace scp::config

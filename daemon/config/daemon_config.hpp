#pragma once
// The daemon's whole configuration as plain structs, filled from YAML by declare_daemon_keys()
// (daemon_keys.cpp), where every key is declared exactly once with its default, range and doc.

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "common/names.hpp"
#include "daemon/core/rt/rt_setup.hpp"
#include "daemon/outputs/server/settings.hpp"
#include "drivers/can/can_settings.hpp"
#include "drivers/modbus/modbus_settings.hpp"
#include "drivers/sim/sim_settings.hpp"
#include "estimator/estimator.hpp"
#include "excitation/excitation_settings.hpp"
#include "health/settings.hpp"
#include "refine/fit_terms.hpp"

namespace scp::config {

class Binder;

// The choices of the file, as the program sees them once read: each table spells the names the
// file uses (and the reference, the errors and the logs show).
enum class DriverType : std::uint8_t { sim, replay, modbus, can };
inline constexpr NameTable<DriverType, 4> kDriverTypes{{{DriverType::sim, "sim"},
                                                        {DriverType::replay, "replay"},
                                                        {DriverType::modbus, "modbus"},
                                                        {DriverType::can, "can"}}};

enum class VelocityMethod : std::uint8_t { central_difference, filtered };
inline constexpr NameTable<VelocityMethod, 2> kVelocityMethods{
    {{VelocityMethod::central_difference, "central_difference"},
     {VelocityMethod::filtered, "filtered"}}};

enum class ExcitationProfile : std::uint8_t { paper, custom };
inline constexpr NameTable<ExcitationProfile, 2> kExcitationProfiles{
    {{ExcitationProfile::paper, "paper"}, {ExcitationProfile::custom, "custom"}}};

enum class LinkTiming : std::uint8_t { automatic, estimate, recorded };
inline constexpr NameTable<LinkTiming, 3> kLinkTimings{{{LinkTiming::automatic, "auto"},
                                                        {LinkTiming::estimate, "estimate"},
                                                        {LinkTiming::recorded, "recorded"}}};

enum class Compression : std::uint8_t { none, gzip };
inline constexpr NameTable<Compression, 2> kCompressions{
    {{Compression::none, "none"}, {Compression::gzip, "gzip"}}};

constexpr const char* to_string(DriverType v) noexcept {
  return name_of(kDriverTypes, v);
}
constexpr const char* to_string(VelocityMethod v) noexcept {
  return name_of(kVelocityMethods, v);
}
constexpr const char* to_string(ExcitationProfile v) noexcept {
  return name_of(kExcitationProfiles, v);
}
// Which interval a row's voltage belongs to (refine/fit_terms.hpp); automatic: `before` (the
// daemon's own drivers and recordings), `estimate` for a replayed file without V_since
// (resolve_voltage_interval).
enum class VoltageIntervalChoice : std::uint8_t { automatic, before, after, estimate };
inline constexpr NameTable<VoltageIntervalChoice, 4> kVoltageIntervals{
    {{VoltageIntervalChoice::automatic, "auto"},
     {VoltageIntervalChoice::before, "before"},
     {VoltageIntervalChoice::after, "after"},
     {VoltageIntervalChoice::estimate, "estimate"}}};

constexpr const char* to_string(LinkTiming v) noexcept {
  return name_of(kLinkTimings, v);
}
constexpr const char* to_string(Compression v) noexcept {
  return name_of(kCompressions, v);
}

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
  VelocityMethod method = VelocityMethod::central_difference;
  double bandwidth_hz = 20.0;
  double damping = 0.7071;
};

struct ReplaySettings {
  std::string file;
};

struct DriverSelection {
  DriverType type = DriverType::sim;
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
  ExcitationProfile profile = ExcitationProfile::paper;
  excitation::ExcitationSettings settings;
};

// Limits that never depend on the estimator: any one exceeded drives 0 V and FAULT.
struct SafetySettings {
  double voltage_max_v = 3.3;
  double temperature_max_c = 100.0;
  double temperature_min_c = -20.0;
  double position_abs_max_m = 0.05;
  double current_max_a = 10.0;    // |heater current| above this is a fault, where it is measured
  double stale_timeout_s = 0.02;  // no fresh reading for this long is a fault
  double recover_after_s = 2.0;   // a driver fault clears after this long healthy; 0 = latch
  double stuck_timeout_s = 0.0;   // x and T bit-identical this long at non-zero output; 0 = off
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
  // samples' timing jitter, estimated, taken as recorded (exact), or automatic: estimated unless
  // the driver is the simulated plant (exact instants); resolved into estimate_link_timing.
  LinkTiming link_timing = LinkTiming::automatic;
  bool estimate_link_timing = false;
  double max_input_delay_s = 0.005;  // the delay is searched within ± this
  // Which interval a row's voltage was applied over; resolved into voltage_interval once the
  // driver is made (resolve_voltage_interval).
  VoltageIntervalChoice voltage_interval_choice = VoltageIntervalChoice::automatic;
  scp::refine::VoltageInterval voltage_interval = scp::refine::VoltageInterval::before;
  // Whether the fit weighs a declared interval against the data (the user's before or after; not
  // the interval a driver or a V_since column states).
  bool check_declared_interval = false;
  // With estimator.voltage_hold foh: how the voltage varied between the rows.
  scp::refine::VoltageShape voltage_shape = scp::refine::VoltageShape::smooth;
  // The nuisance terms (estimated unless fixed) and the model's extensions (issue 28).
  scp::refine::NuisanceSettings nuisance;
  scp::refine::ExtensionSettings extensions;
  // The sensors' declared white-noise σ (x in m, T̄ in °C; 0 = not declared), from sensors.noise:
  // the validation's noise-ratio tests.
  std::array<double, 2> declared_noise{};
};

// Actuator health (docs/health.md): the monitor's settings and where its baseline comes from.
struct HealthConfig {
  health::HealthSettings settings;
  // A baseline made elsewhere; "" = <state.directory>/<actuator.name>.baseline.json, saved with
  // `scp-estimatorctl baseline save`.
  std::string baseline_file;
};

// The Prometheus textfile the daemon writes (docs/metrics: node_exporter's textfile collector).
struct MetricsSettings {
  std::string textfile_directory;  // "" = no textfile
  double interval_s = 15.0;
};

// Recording in service mode: rotating CSV files written by a non-real-time thread.
struct RecordingSettings {
  std::string directory;                     // "" = no recording
  double rotate_size_mib = 64.0;             // a new file after this many MiB (0 = no size limit)
  double rotate_interval_s = 3600.0;         // a new file after this long (0 = no time limit)
  std::size_t keep_files = 168;              // older files are deleted (0 = keep all)
  Compression compress = Compression::none;  // rotated files, by a thread below the recorder
};

struct DaemonConfig {
  std::string source;  // file it came from, for messages and `status`
  LoopSettings loop;
  ActuatorSettings actuator;
  DriverSelection driver;
  estimator::EstimatorConfig estimator;
  ExcitationConfig excitation;
  SafetySettings safety;
  daemon::server::ServerSettings socket;  // the server's own settings, filled from `socket`
  StateSettings state;
  RefineSettings refine;
  HealthConfig health;
  MetricsSettings metrics;
  RecordingSettings recording;
  std::string log_level = "info";
};

// Fills the settings that other keys decide: the estimator's sample period and input validity
// follow the loop and the safety limits, the simulated sensor reads the actuator's ambient, the
// paper's excitation profile, the refinement's link timing. The loader calls it after reading;
// a test that starts from the structs' defaults calls it to get what an empty file gives.
void derive_settings(DaemonConfig& config);
// refine.voltage_interval into RefineSettings::voltage_interval, once the driver is made: `auto`
// is before when the driver stamps when each voltage took effect
// (drivers::Driver::stamps_voltage_instants), else estimate. Service and batch runs alike.
void resolve_voltage_interval(RefineSettings& refine, bool driver_stamps_voltage) noexcept;

// Declares every key on `root` and fills `out`. Throws ConfigError naming key, line and range.
void declare_daemon_keys(Binder& root, DaemonConfig& out);

// Reads and validates a file (unknown keys are errors). Throws ConfigError.
DaemonConfig load_config_file(const std::string& path);
// The same from YAML text (tests, fuzzing). `name` appears in messages.
DaemonConfig load_config_text(const std::string& text, const std::string& name);
// Markdown reference of every key (scp-estimatord --print-config-reference).
std::string config_reference_markdown();

}  // namespace scp::config

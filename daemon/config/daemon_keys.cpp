// Every key of the daemon's configuration, declared once: default, range, one line of doc.
// `scp-estimatord --print-config-reference` prints this table; docs/configuration.md is its output.

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <tuple>

#include "daemon/config/binder.hpp"
#include "daemon/config/config_file.hpp"
#include "daemon/config/daemon_config.hpp"
#include "daemon/config/keys_can.hpp"
#include "daemon/config/keys_modbus.hpp"
#include "daemon/programs/cli/instance_names.hpp"
#include "drivers/modbus/timing.hpp"
#include "drivers/sim/sim_driver.hpp"
#include "excitation/excitation.hpp"
#include "refine/fit.hpp"

namespace scp::config {

namespace {

constexpr double kHuge = 1e300;
constexpr double kMaxRefineSamples = 1e6;  // window samples held in memory at most

void declare_loop(Binder loop, LoopSettings& out) {
  loop.number("period_s", out.period_s, 0.001, 1e-4, 1.0,
              "loop period in seconds (1 kHz = 0.001); also the estimator's sample period");
  loop.number("overrun_warning_interval_s", out.overrun_warning_interval_s, 10.0, 0.1, 3600.0,
              "at most one log line about overruns per this many seconds");
  Binder rt = loop.section("realtime", "real-time set-up of the loop thread");
  rt.integer("priority", out.realtime.priority, 80, 0, 99,
             "SCHED_FIFO priority of the loop thread; 0 = ordinary scheduling");
  int cpu = -1;
  rt.integer("cpu", cpu, -1, -1, 1023, "CPU the loop thread is pinned to; -1 = any");
  out.realtime.cpus.clear();
  if (cpu >= 0) out.realtime.cpus.push_back(cpu);
  rt.boolean("lock_memory", out.realtime.lock_memory, true,
             "mlockall() and prefault the heap so the loop never page-faults");
  std::size_t heap_mib = 0;
  rt.integer("prefault_heap_mib", heap_mib, 0, 0, 4096, "MiB of heap touched at start-up");
  out.realtime.prefault_heap_bytes = heap_mib << 20;
  rt.boolean("required", out.realtime.required, false,
             "true: fail to start when any real-time setting cannot be applied (else: warn)");
}

void declare_actuator(Binder actuator, ActuatorSettings& out) {
  actuator.text("name", out.name, "scp-estimator",
                "name of this actuator: kept in its checkpoint (a warm start from another "
                "actuator's checkpoint is refused), the actuator label of its metrics, shown in "
                "STATUS; give each actuator on a PC its own (letters, digits, '.', '_', '-')");
  if (!cli::is_plain_name(out.name)) {
    actuator.fail("name", "'" + out.name +
                              "' is not a name of 1-64 letters, digits, '.', '_' or '-'; choose "
                              "one such as bench-a");
  }
  actuator.number("ambient_c", out.ambient_c, 25.0, -50.0, 100.0,
                  "ambient temperature in °C; the model uses T̄ = T − ambient");
  actuator.number("mass_kg", out.mass_kg, 0.0, 0.0, 1e3,
                  "moving mass m incl. load; with resistance_ohm lets the daemon report b, k, "
                  "α1, α2, λ, Cth (0 = unknown)");
  actuator.number("resistance_ohm", out.resistance_ohm, 0.0, 0.0, 1e6,
                  "electrical resistance R of the heater (0 = unknown)");
}

void declare_sim(Binder& sim, drivers::sim::SimSettings& out) {
  Binder plant = sim.section("plant", "physical parameters of the simulated actuator (Table I)");
  auto& p = out.plant;
  plant.number("m", p.m, 0.1, 1e-6, 1e3, "mass in kg");
  plant.number("R", p.R, 1.0, 1e-6, 1e6, "resistance in Ω");
  plant.number("Cth", p.Cth, 0.9090, 1e-6, 1e6, "thermal mass in Ws/°C");
  plant.number("lambda", p.lambda, 0.0540, 1e-9, 1e6, "heat conductivity in W/°C");
  plant.number("b", p.b, 124.7, 0.0, 1e9, "damping in Ns/m");
  plant.number("k", p.k, 181.3, 1e-9, 1e9, "stiffness in N/m");
  plant.number("alpha1", p.alpha1, 0.08, 0.0, 1e6, "thermal damping coefficient in Ns/(m·°C)");
  plant.number("alpha2", p.alpha2, 0.01, -1e6, 1e6, "thermal stiffness coefficient in N/°C");
  sim.integer("substeps", out.substeps, 20, 1, 1000, "RK4 sub-steps per millisecond of plant time");
  Binder noise = sim.section("noise", "Gaussian sensor noise, standard deviation (0 = none)");
  noise.number("x", out.noise_x, 0.0, 0.0, 1.0, "on x, in m");
  noise.number("xdot", out.noise_xdot, 0.0, 0.0, 10.0, "on ẋ, in m/s");
  noise.number("temperature", out.noise_temperature, 0.0, 0.0, 100.0, "on T, in °C");
  noise.number("voltage", out.noise_voltage, 0.0, 0.0, 10.0, "on the voltage read back, in V");
  noise.number("correlation_s", out.noise_correlation_s, 0.0, 0.0, 100.0,
               "correlation time of every channel's noise, s: 0 = white, else a first-order "
               "Gauss-Markov process with the standard deviations above (a filtered sensor)");
  noise.integer("seed", out.seed, 1, 0, std::uint64_t{1} << 62, "seed of the noise generator");
  sim.boolean("measure_xdot", out.measure_xdot, true,
              "false: the simulated device has no velocity sensor (ẋ is estimated from x)");
  Binder drift = sim.section("drift", "relative drift per hour of each physical parameter");
  auto& d = out.drift;
  drift.number("m", d.m, 0.0, -10.0, 10.0, "of m, per hour");
  drift.number("R", d.R, 0.0, -10.0, 10.0, "of R, per hour");
  drift.number("Cth", d.Cth, 0.0, -10.0, 10.0, "of Cth, per hour");
  drift.number("lambda", d.lambda, 0.0, -10.0, 10.0, "of λ, per hour");
  drift.number("b", d.b, 0.0, -10.0, 10.0, "of b, per hour");
  drift.number("k", d.k, 0.0, -10.0, 10.0, "of k, per hour");
  drift.number("alpha1", d.alpha1, 0.0, -10.0, 10.0, "of α1, per hour");
  drift.number("alpha2", d.alpha2, 0.0, -10.0, 10.0, "of α2, per hour");
  Binder step = sim.section("step", "a step of one physical parameter, for tests of health");
  step.choice("parameter", out.step_parameter, "none", drivers::sim::kStepParameterNames,
              "the physical parameter that steps (none = no step)");
  step.number("at_s", out.step_at_s, 0.0, 0.0, kHuge, "loop time of the step");
  step.number("factor", out.step_factor, 1.0, 1e-3, 1e3, "the parameter is multiplied by this");
  Binder fault = sim.section("fault", "fault injection, for tests of the safety layer");
  fault.choice("kind", out.fault, "none",
               {"none", "nan_temperature", "inf_position", "stuck_position", "stuck_sensor",
                "temperature_out_of_range", "read_error", "no_data", "stall"},
               "sensor fault to inject");
  fault.number("start_s", out.fault_start_s, 0.0, 0.0, kHuge, "loop time at which it begins");
  fault.number("duration_s", out.fault_duration_s, 0.0, 0.0, kHuge, "how long (0 = forever)");
  fault.number("value_c", out.fault_value_c, 400.0, -1e6, 1e6,
               "temperature reported by temperature_out_of_range, °C");
}

// How the simulated bench departs from the paper's model (issue 28): the same deviations a real
// bench has, for tests of the refinement's nuisance terms, extensions and validation.
void declare_sim_bench(Binder& sim, drivers::sim::SimSettings& out) {
  auto& d = out.deviations;
  Binder tempco = sim.section("tempco",
                              "temperature coefficients of the simulated plant, 1/°C of "
                              "T̄ from the true ambient (0 = the paper's model)");
  tempco.number("R", d.resistance_tempco, 0.0, -0.02, 0.02,
                "heater resistance R(T̄) = R0·(1 + ρT̄); a nickel heater has 0.0059");
  tempco.number("k_softening", d.stiffness_softening, 0.0, -0.02, 0.02,
                "stiffness softening k(T̄) = k0·(1 − κT̄); nylon softens when heated");
  tempco.number("lambda", d.cooling_tempco, 0.0, -0.02, 0.02,
                "cooling λ(T̄) = λ0·(1 + γT̄); free convection grows with T");
  Binder ambient = sim.section("ambient", "the true ambient of the simulated bench");
  ambient.number("offset_c", d.ambient_offset_c, 0.0, -50.0, 50.0,
                 "°C the true ambient lies above actuator.ambient_c");
  ambient.number("drift_c_per_h", d.ambient_drift_c_per_h, 0.0, -100.0, 100.0,
                 "°C per hour the true ambient moves (linear)");
  Binder sensor = sim.section("sensor", "the simulated sensors' systematic errors");
  sensor.number("x_zero_m", out.x_zero, 0.0, -1.0, 1.0,
                "what the displacement sensor reads at rest (m)");
  sensor.number("temperature_lag_s", d.temperature_lag_s, 0.0, 0.0, 100.0,
                "first-order lag of the temperature sensor, s (0 = none, else at least 0.001: "
                "the RK4 sub-steps must resolve it); a fine thermocouple lags 0.1-0.5 s");
  if (d.temperature_lag_s > 0.0 && d.temperature_lag_s < 1e-3) {
    sensor.fail("temperature_lag_s",
                "must be 0 (no lag) or at least 0.001 s; the plant's sub-steps cannot resolve a "
                "shorter lag");
  }
  sim.boolean("measure_current", out.measure_current, false,
              "the simulated DAQ also measures the heater current I = V/R(T̄)");
  sim.number("noise_current", out.noise_current, 0.0, 0.0, 10.0,
             "Gaussian noise on the heater current, standard deviation in A");
}

void declare_driver(Binder driver, DriverSelection& out) {
  driver.choice("type", out.type, DriverType::sim, kDriverTypes, "which device the loop talks to");
  driver.number("start_timeout_s", out.start_timeout_s, 0.0, 0.0, 86400.0,
                "s a device absent or silent at start is awaited (STARTING, 0 V, retried with "
                "back-off) before the daemon exits with 69 (EX_UNAVAILABLE, not restarted by the "
                "unit); 0 = wait without limit");
  Binder sim = driver.section("sim", "the simulated SCP actuator (type: sim)");
  declare_sim(sim, out.sim);
  declare_sim_bench(sim, out.sim);
  Binder replay = driver.section("replay", "a recorded CSV played back (type: replay)");
  replay.text("file", out.replay.file, "",
              "CSV with header t,x,xdot,T,V (SI units, T in °C; t increasing, gaps allowed)");
  Binder modbus = driver.section("modbus", "a Modbus DAQ, TCP or RTU (type: modbus)");
  declare_modbus_keys(modbus, out.modbus);
  Binder can = driver.section("can", "a SocketCAN device (type: can)");
  declare_can_keys(can, out.can);
  Binder velocity = driver.section("velocity", "ẋ estimated from x when the device has no ẋ");
  velocity.choice("method", out.velocity.method, VelocityMethod::central_difference,
                  kVelocityMethods,
                  "central_difference: 3-point derivative, every signal delayed one sample to "
                  "match (no bias); filtered: causal differentiator whose lag biases θ1..θ4");
  velocity.number("bandwidth_hz", out.velocity.bandwidth_hz, 20.0, 0.01, 1e4,
                  "bandwidth of the filtered differentiator (lag ≈ 2ζ/ωc)");
  velocity.number("damping", out.velocity.damping, 0.7071, 0.1, 5.0,
                  "damping ratio ζ of the differentiator's filter");
}

void declare_estimator(Binder est, estimator::EstimatorConfig& out) {
  est.number("beta", out.beta, 3.0, 1e-3, 1e4, "filter pole β in rad/s, eqs. (9)-(15)");
  est.number("forgetting", out.forgetting, 0.8, 1e-6, 1e3, "forgetting rate λP in 1/s, eq. (25)");
  est.number("forgetting_mechanical", out.forgetting_mechanical, 0.0, 0.0, 1e3,
             "λP of the mechanical block θ1..θ4 alone, 1/s; 0 = use estimator.forgetting. Larger "
             "follows a "
             "drifting b with less lag (scripts/soak uses 10), smaller passes less noise");
  est.number("p0", out.p0, 100.0, 1e-12, 1e30,
             "P(0) = p0·diag(scale)²; the paper: 100 with scale all 1");
  est.number("p_max", out.p_max, 1e10, 1e-12, 1e30,
             "bound on P (scaled coordinates): forgetting never drains information below 1/p_max");
  std::vector<double> theta0;
  est.numbers("theta0", theta0, {0, 0, 0, 0, 0, 0}, 6, -1e9, 1e9,
              "initial θ̂ = [b/m, α1/m, k/m, α2/m, λ/Cth, 1/(R·Cth)]; the paper: zeros");
  for (int i = 0; i < 6; ++i) out.theta0[i] = theta0[static_cast<std::size_t>(i)];
  std::vector<double> scale;
  est.numbers("scale", scale, {1, 1, 1, 1, 1, 1}, 6, 1e-12, 1e12,
              "parameter scale D (θ = D·ϑ), about |θ| is sensible; the paper: ones");
  for (int i = 0; i < 6; ++i) out.scale[i] = scale[static_cast<std::size_t>(i)];
  std::vector<double> known;
  est.numbers("known", known, {0, 0, 0, 0, 0, 0}, 6, 0, 1,
              "1 = θ_i is known and held at theta0 (e.g. k/m from a static stiffness test: it "
              "fixes the scale of θ1..θ4 that the data barely show); 0 = estimated");
  for (std::size_t i = 0; i < 6; ++i) {
    if (known[i] != 0.0 && known[i] != 1.0) {
      char value[32];
      std::snprintf(value, sizeof value, "%g", known[i]);
      est.fail("known", "known[" + std::to_string(i) + "] is " + value +
                            "; each entry is 0 (estimated) or 1 (known, held at theta0)");
    }
    out.known[i] = known[i] == 1.0;
  }
  std::string hold;
  est.choice("voltage_hold", hold, "zoh", {"zoh", "foh"},
             "zoh: the voltage is held by a DAC over each period (exact); foh: interpolated");
  out.voltage_hold = hold == "foh" ? estimator::VoltageHold::foh : estimator::VoltageHold::zoh;
  est.number("max_gap_periods", out.max_gap_periods, 10.0, 1.5, 1e6,
             "a gap between samples longer than this many periods restarts the filters");
  est.number("xdot_abs_max", out.xdot_abs_max, 10.0, 1e-9, 1e6,
             "|ẋ| above this (m/s) is an invalid sample, skipped and counted");
  est.number("converged_rel_sigma", out.converged_rel_sigma, 0.01, 1e-12, 10.0,
             "a block counts as converged when every σ_i/|θ̂_i| is below this");
}

void declare_excitation(Binder exc, ExcitationConfig& out) {
  exc.boolean("enabled", out.enabled, true,
              "excite at start (else hold 0 V until `excitation on`)");
  exc.choice("profile", out.profile, ExcitationProfile::paper, kExcitationProfiles,
             "paper: the four-sine voltage of Section IV; custom: the keys below");
  auto& s = out.settings;
  exc.number("v_max", s.v_max, 3.2, 0.0, 1e3, "upper clamp of the excitation in V (custom)");
  exc.number("offset_v", s.offset, 0.0, -1e3, 1e3, "constant part in V (custom)");
  s.sines.clear();
  exc.list("sines", "sum of sines (custom)", [&](Binder& item, std::size_t) {
    excitation::Sine sine;
    item.number("amplitude_v", sine.amplitude, 0.0, -1e3, 1e3, "amplitude in V");
    item.number("frequency_hz", sine.frequency_hz, 1.0, 1e-9, 1e4, "frequency in Hz");
    item.number("phase_rad", sine.phase_rad, 0.0, -1e3, 1e3, "phase in rad: A·sin(2πft + phase)");
    if (!item.is_template()) s.sines.push_back(sine);
  });
  s.steps.clear();
  exc.list("steps", "steps (custom): from time_s on, level_v is added",
           [&](Binder& item, std::size_t) {
             excitation::Step step;
             item.number("time_s", step.time_s, 0.0, 0.0, kHuge, "time the step occurs, s");
             item.number("level_v", step.level_v, 0.0, -1e3, 1e3, "height of the step in V");
             if (!item.is_template()) s.steps.push_back(step);
           });
  Binder prbs = exc.section("prbs", "pseudo-random binary sequence (custom)");
  prbs.number("amplitude_v", s.prbs.amplitude, 0.0, 0.0, 1e3, "±amplitude in V; 0 disables it");
  prbs.number("bit_period_s", s.prbs.bit_period_s, 1.0, 1e-4, 1e6, "duration of one bit");
  prbs.integer("order", s.prbs.order, 7, 2, 31,
               "LFSR order; the sequence repeats after 2^order − 1 bits");
  prbs.integer("seed", s.prbs.seed, 1, 1, 0x7fffffff, "LFSR seed (non-zero)");
}

void declare_safety(Binder safety, SafetySettings& out) {
  safety.number("voltage_max_v", out.voltage_max_v, 3.3, 0.0, 1e3,
                "hard limit on the command; a read-back above it is a fault");
  safety.number("temperature_max_c", out.temperature_max_c, 100.0, -50.0, 1000.0,
                "actuator temperature above this is a fault (0 V)");
  safety.number("temperature_min_c", out.temperature_min_c, -20.0, -273.0, 1000.0,
                "actuator temperature below this is a fault (a broken sensor reads low)");
  safety.number("position_abs_max_m", out.position_abs_max_m, 0.05, 1e-9, 10.0,
                "|x| above this is a fault");
  safety.number("current_max_a", out.current_max_a, 10.0, 1e-6, 1e4,
                "|heater current| above this is a fault (a short circuit, or a wrong scale in "
                "the driver's map); checked only where the device measures the current");
  safety.number("stale_timeout_s", out.stale_timeout_s, 0.02, 1e-4, 60.0,
                "no fresh reading for this long is a fault");
  safety.number("recover_after_s", out.recover_after_s, 2.0, 0.0, 3600.0,
                "a driver fault (failed transaction, lost link, stale data) clears by itself "
                "after this long with fresh valid readings; 0 = latch it. Limit and sensor-value "
                "faults always latch until clear-fault");
  safety.number("stuck_timeout_s", out.stuck_timeout_s, 0.0, 0.0, 3600.0,
                "x and T bit-identical for this long while the output is non-zero is a sensor "
                "fault (a dead sensor repeating its last value); latches. 0 = off");
}

void declare_socket(Binder socket, daemon::server::ServerSettings& out) {
  socket.text("path", out.socket_path, "/run/scp-estimator/scp-estimator.sock",
              "Unix socket of the JSON API");
  socket.text("group", out.group, "",
              "group whose members may send mutating requests (reset, excitation, clear-fault)");
  std::string mode;
  socket.text("mode", mode, "0660", "permissions of the socket file, octal");
  std::size_t used = 0;
  unsigned long parsed = 0;
  try {
    parsed = std::stoul(mode, &used, 8);
  } catch (const std::exception&) {
    used = 0;
  }
  // An empty text would parse as nothing and leave mode 0000: nobody could connect.
  if (mode.empty() || used != mode.size() || parsed > 0777) {
    socket.fail("mode", "'" + mode + "' is not an octal permission such as 0660 (range 0000-0777)");
  }
  out.mode = static_cast<unsigned>(parsed);
  socket.integer("max_clients", out.max_clients, 128, 1, 4096, "clients connected at once");
  socket.integer("max_line_bytes", out.max_line, 4096, 256, 1 << 20,
                 "longest request line; longer ones are refused and the client dropped");
  socket.number("idle_timeout_s", out.idle_timeout_s, 300.0, 0.1, 1e6,
                "clients silent this long (and not watching) are dropped");
}

void declare_state(Binder state, StateSettings& out) {
  state.text("directory", out.directory, "/var/lib/scp-estimator",
             "where estimator.state is checkpointed (systemd StateDirectory)");
  state.number("checkpoint_interval_s", out.checkpoint_interval_s, 60.0, 0.1, 1e6,
               "seconds between checkpoints (and one at shutdown)");
  state.boolean("warm_start", out.warm_start, true,
                "resume θ̂ and its covariance from the checkpoint at start");
  state.number("warm_start_theta_max", out.warm_start_theta_max, 1e6, 1.0, 1e12,
               "a checkpoint whose |θ̂_i| exceeds this many times max(estimator.scale_i, "
               "|estimator.theta0_i|) is refused (cold start): a poisoned or diverged state "
               "must not seed the estimator");
}

void declare_refine(Binder& refine, RefineSettings& out) {
  refine.boolean("enabled", out.enabled, true,
                 "run the output-error refinement beside the paper's law (a worker thread "
                 "below the loop; in --offline runs --jobs threads beside it, or inline)");
  refine.number("window_s", out.window_s, 300.0, 1.0, 3600.0,
                "loop time of the sliding window fitted; memory " +
                    std::to_string(sizeof(scp::refine::WindowSample)) +
                    " bytes per sample of it (window_s / loop.period_s samples, locked with the "
                    "rest; the solver streams its sensitivities)");
  refine.number("interval_s", out.interval_s, 10.0, 0.01, 3600.0,
                "a fit every this much loop time once min_window_s of data are there (after a "
                "fit whose model the window rejects, when the window is full, or 4x as long if it "
                "was shorter than the thermal time constant, or once full renewed); "
                "the refined estimate stops being `best` when its fit is older than 3 intervals");
  refine.number("min_window_s", out.min_window_s, 30.0, 0.01, 3600.0,
                "no fit on less data than this (a gap starts a new window); at most window_s");
  refine.integer("max_iterations", out.max_iterations, 100, 1, 100000,
                 "iterations of the solver per fit before it gives up (converged: false)");
  refine.integer("hac_lags", out.hac_lags, 0, 0, 100000,
                 "residual autocorrelation lags of the Newey-West covariance; 0 = automatic "
                 "(floor(4·(N/100)^(2/9)))");
  refine.integer("covariance_batches", out.covariance_batches, 20, 0, 1000,
                 "batches of the batch-means check on σ: a σ is scaled up "
                 "(`refined.sigma_inflation`) where the score summed over this many contiguous "
                 "batches of the window varies significantly (99 %) more than the Newey–West "
                 "covariance allows, i.e. an error slower than its lags, such as a link's "
                 "timing. 0 or 1 = no check (docs/numerics.md, \"σ on a real link\")");
  refine.number("max_gap_s", out.max_gap_s, 0.2, 1e-4, 60.0,
                "a step between two samples longer than this starts a new window. Shorter gaps "
                "(missed periods, failed reads, a stalled link) are simulated through with the "
                "voltage the DAC held, which keeps the window long on a jittery link; keep it "
                "below the timeout of a device watchdog that drops the output (the voltage "
                "during a longer gap is not known)");
  refine.choice("link_timing", out.link_timing, LinkTiming::automatic, kLinkTimings,
                "`estimate`: fit the voltage's delay relative to the instants the driver "
                "recorded for it (a DAQ's output latency, a gateway's turnaround) from T, and the "
                "samples' timing jitter with the noise, down-weighting samples far outside it "
                "(stamps a load spike displaced) and filtering T for the landings' jitter; "
                "θ1..θ4 need all of it on a real link (docs/numerics.md, \"Time on a real "
                "link\"). `recorded`: the instants are exact. `auto`: estimate unless "
                "driver.type is sim");
  refine.number("max_input_delay_s", out.max_input_delay_s, 0.005, 1e-6, 1.0,
                "the delay is searched within ± this; a fit whose delay lands on the limit does "
                "not converge");
}

// A nuisance term: `estimate` (the default) or the number it is held at, in [min, max] of the
// key's unit (the fit's unit is the key's times `scale`).
void nuisance_key(Binder& b, std::string_view key, scp::refine::NuisanceSetting& out, double min,
                  double max, double scale, std::string_view doc) {
  std::optional<double> held;
  b.number_or_word(key, held, "estimate", "estimate", min, max, doc);
  out = {.fixed = held.has_value(), .value = held.value_or(0.0) * scale};
}

// The temperature sensor's lag: `estimate`d like the other nuisance terms (refine/sensor_lag.hpp),
// or held at a declared time constant (0: none).
void declare_sensor_lag(Binder& nuisance, RefineSettings& out) {
  nuisance_key(nuisance, "sensor_lag", out.nuisance.sensor_lag, 0.0, 100.0, 1.0,
               "first-order lag of the temperature sensor, s: `estimate`, or the time constant "
               "when known (0: none)");
}

// The extensions ρ, κ, γ of the paper's model (refine/fit_terms.hpp): `off`, `on` or `auto`
// (kept where Schwarz's BIC says the window needs it).
void declare_extensions(Binder& refine, RefineSettings& out) {
  Binder ext = refine.section("extensions",
                              "extensions of the paper's model: off, on, or auto (fitted, and "
                              "kept where the BIC says the window needs it; docs/numerics.md)");
  const std::tuple<const char*, scp::refine::ExtensionMode*, const char*> exts[] = {
      {"resistance_tempco", &out.extensions.resistance_tempco,
       "the heater's resistance's temperature coefficient ρ: R = R0·(1 + ρT̄), the heating "
       "θ6·V²/(1 + ρT̄)"},
      {"stiffness_softening", &out.extensions.stiffness_softening,
       "the stiffness's softening κ: k = k0·(1 − κT̄), a force +θ3·κ·T̄·x"},
      {"cooling_tempco", &out.extensions.cooling_tempco,
       "the cooling's temperature coefficient γ: λ = λ0·(1 + γT̄), the cooling "
       "−θ5·(1 + γT̄)·T̄"}};
  for (const auto& [key, mode, doc] : exts)
    ext.choice(key, *mode, scp::refine::ExtensionMode::off, scp::refine::kExtensionModeNames, doc);
}

// What the refined fit is told about a real bench (refine/fit_terms.hpp, issue 28).
void declare_refine_bench(Binder& refine, RefineSettings& out) {
  refine.choice(
      "voltage_interval", out.voltage_interval_choice, VoltageIntervalChoice::automatic,
      kVoltageIntervals,
      "which interval a row's voltage was applied over: `before` its sample (the "
      "daemon's drivers and recordings, V_since), `after` it (a log writing the command "
      "issued at t), `estimate` (fit both, keep the better; when the data cannot tell them "
      "apart, refined.voltage_interval reads `undetermined` and `best` keeps off the refined "
      "estimate). `auto`: before, except estimate for a replayed file (--replay or "
      "driver.type: replay) without a V_since column. A declared before or after is weighed "
      "against the data as estimate would; where the data decide for the other, "
      "voltage_interval_test reads `contradicted` and `best` keeps off the refined estimate");
  refine.choice("voltage_shape", out.voltage_shape, scp::refine::VoltageShape::smooth,
                scp::refine::kVoltageShapeNames,
                "with estimator.voltage_hold foh, how the voltage varied between the rows: "
                "`smooth` (a continuous drive sampled at the rows: V² from the cubic through four "
                "rows, and a switch of a PRBS or step held from the place in its interval that "
                "fits T̄ best, then each switch placed from the residuals where the data ask for "
                "it, refined.voltage_switches) or `linear` (a DAC ramping from one command to the "
                "next)");
  Binder nuisance = refine.section("nuisance",
                                   "nuisance terms of a real bench, estimated beside θ unless "
                                   "held at a declared value (published in refined.nuisance)");
  nuisance_key(nuisance, "x_zero", out.nuisance.x_zero, -1.0, 1.0, 1.0,
               "what the displacement sensor reads at the true rest position, m");
  nuisance_key(nuisance, "ambient_offset", out.nuisance.ambient_offset, -50.0, 50.0, 1.0,
               "°C the true ambient lies above actuator.ambient_c");
  nuisance_key(nuisance, "ambient_drift", out.nuisance.ambient_drift, -100.0, 100.0, 1.0 / 3600.0,
               "°C per hour the ambient moves over the window");
  declare_sensor_lag(nuisance, out);
  declare_extensions(refine, out);
}

void declare_sensors(Binder sensors, RefineSettings& out) {
  Binder noise = sensors.section("noise",
                                 "the sensors' white-noise standard deviation, as their data "
                                 "sheets or a rest measurement say (0 = not declared): the "
                                 "refinement's validation tests the residuals against it");
  noise.number("x_m", out.declared_noise[0], 0.0, 0.0, 1.0, "of the displacement sensor, m");
  noise.number("temperature_c", out.declared_noise[1], 0.0, 0.0, 100.0,
               "of the temperature sensor, °C");
}

void declare_health(Binder health, HealthConfig& out) {
  health::HealthSettings& h = out.settings;
  health.number("false_alarm_days", h.false_alarm_days, 30.0, 0.01, 1e5,
                "designed mean running time between false alarms of all detectors together "
                "(days); the thresholds follow from it (docs/health.md)");
  health.number("drift_per_hour", h.drift_per_hour, 0.05, 1e-6, 10.0,
                "a parameter whose slope exceeds this fraction of |θ_i| per hour "
                "(significantly) raises `drift`");
  health.number("min_relative_change", h.min_relative_change, 0.02, 0.0, 1.0,
                "no parameter is named as changed by less than this fraction of |θ_i|, however "
                "significant (a real bench's model misfit moves θ̂ by more than its σ)");
  health.number("design_change", h.design_change, 0.10, 1e-6, 10.0,
                "the step, as a fraction of |θ_i|, the fast detector's CUSUMs are tuned for");
  health.number("block_s", h.block_s, 1.0, 1e-3, 600.0,
                "the fast detector sums the residuals' scores over blocks this long");
  health.number("trend_span_s", h.trend_span_s, 3600.0, 60.0, 1e6,
                "the drift test's trends use the refined windows of this much loop time");
  health.number("reference_span_s", h.reference_span_s, 1200.0, 60.0, 1e6,
                "the reference the detectors test against extrapolates the trend of this much "
                "loop time of refined windows (at least three refine.window_s)");
  health.number("trend_min_span_s", h.trend_min_span_s, 0.0, 0.0, 1e6,
                "the reference takes a slope once its windows' midpoints span this long (0: "
                "from two windows)");
  health.number("heat_capacity_j_per_c", h.heat_capacity_j_per_c, 0.0, 0.0, 1e9,
                "the actuator's heat capacity Cth in J/°C when known (R and λ are then "
                "published); 0 = unknown");
  Binder baseline = health.section("baseline", "the healthy actuator the monitor compares with");
  baseline.text("file", out.baseline_file, "",
                "a baseline made elsewhere (scp-estimatorctl baseline show prints the format); "
                "\"\" = <state.directory>/<actuator.name>.baseline.json, written by "
                "`scp-estimatorctl baseline save`");
  // Each key's range is the Binder's; what is left are the two relations between keys.
  if (h.reference_span_s > h.trend_span_s) {
    health.fail("reference_span_s",
                "must not exceed health.trend_span_s (the reference is taken from the windows "
                "the trend keeps)");
  }
  if (h.trend_min_span_s > h.trend_span_s) {
    health.fail("trend_min_span_s", "must not exceed health.trend_span_s");
  }
}

void declare_metrics(Binder metrics, MetricsSettings& out) {
  metrics.text("textfile_directory", out.textfile_directory, "",
               "directory of node_exporter's textfile collector; the daemon writes "
               "<actuator.name>.prom there every interval_s (temporary file, then rename). "
               "\"\" = none. Under systemd, allow it with ReadWritePaths= in a drop-in");
  metrics.number("interval_s", out.interval_s, 15.0, 1.0, 3600.0,
                 "seconds between two writes of the textfile");
}

void declare_recording(Binder recording, RecordingSettings& out) {
  recording.text("directory", out.directory, "",
                 "record every sample the estimator is fed to rotating CSV files here "
                 "(<actuator.name>-<UTC time>.csv; \"\" = no recording). The files replay with "
                 "--replay as they are. Under systemd, allow it with ReadWritePaths=");
  recording.number("rotate_size_mib", out.rotate_size_mib, 64.0, 0.0, 1e6,
                   "start a new file after this many MiB (0 = no size limit)");
  recording.number("rotate_interval_s", out.rotate_interval_s, 3600.0, 0.0, 1e9,
                   "start a new file after this many seconds (0 = no time limit)");
  recording.integer("keep_files", out.keep_files, 168, 0, 1000000,
                    "delete the oldest of this actuator's recordings beyond this many (0 = keep "
                    "all; a compressed file counts like a plain one)");
  recording.choice("compress", out.compress, Compression::none, kCompressions,
                   "gzip: compress each file once it is rotated (<name>.csv.gz, written to a "
                   "temporary file, synced, renamed; then the plain file is deleted) on a "
                   "low-priority thread; the file being written stays plain. --replay reads both. "
                   "Default none: plain files can be read by any tool while being written, and "
                   "compression costs CPU time on the machine that runs the loop (measured in "
                   "docs/recording.md)");
}

// Checks that span keys or belong to the libraries' own validation; reported as ConfigErrors.
void cross_check(const Binder& root, DaemonConfig& cfg) {
  derive_settings(cfg);
  const auto& est = cfg.estimator;
  if (cfg.safety.temperature_min_c >= cfg.safety.temperature_max_c) {
    root.fail("safety", "safety.temperature_min_c must be below safety.temperature_max_c");
  }
  if (cfg.actuator.ambient_c <= cfg.safety.temperature_min_c ||
      cfg.actuator.ambient_c >= cfg.safety.temperature_max_c) {
    root.fail("actuator",
              "actuator.ambient_c must lie between safety.temperature_min_c and "
              "safety.temperature_max_c");
  }
  if (est.p0 > est.p_max) {
    root.fail("estimator", "estimator.p0 must not exceed estimator.p_max");
  }
  if (cfg.refine.min_window_s > cfg.refine.window_s) {
    root.fail("refine", "refine.min_window_s must not exceed refine.window_s");
  }
  // The window is preallocated (daemon/analysis/refine/sample_window.hpp); refuse a size that would
  // not fit.
  if (cfg.refine.enabled && cfg.refine.window_s / cfg.loop.period_s > kMaxRefineSamples) {
    root.fail("refine", "refine.window_s / loop.period_s is " +
                            std::to_string(std::llround(cfg.refine.window_s / cfg.loop.period_s)) +
                            " samples; at most " + std::to_string(std::llround(kMaxRefineSamples)) +
                            " fit in memory: shorten refine.window_s");
  }
  if (cfg.driver.type == DriverType::replay && cfg.driver.replay.file.empty()) {
    root.fail("driver", "driver.type is replay but driver.replay.file is empty: name the CSV");
  }
  try {
    estimator::Estimator probe(est);
    excitation::validate(cfg.excitation.settings);
    if (cfg.driver.type == DriverType::sim) drivers::sim::SimDriver probe_sim(cfg.driver.sim);
    // The timing budget, so that --check-config refuses it too, not only the driver's open().
    if (cfg.driver.type == DriverType::modbus)
      drivers::modbus::check_timing(cfg.driver.modbus, cfg.loop.period_s);
  } catch (const std::exception& e) {
    throw ConfigError(cfg.source + ": " + e.what());
  }
}

DaemonConfig load_node(const YAML::Node& root_node, const std::string& name) {
  DaemonConfig cfg;
  cfg.source = name;
  Binder root = Binder::reading(root_node, name);
  declare_daemon_keys(root, cfg);
  root.reject_unknown_keys();
  cross_check(root, cfg);
  return cfg;
}

YAML::Node parse_yaml(const std::string& text, const std::string& name) {
  try {
    return YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw ConfigError(name + ":" + std::to_string(e.mark.line + 1) + ": not valid YAML: " + e.msg);
  }
}

}  // namespace

void declare_daemon_keys(Binder& root, DaemonConfig& out) {
  declare_loop(root.section("loop", "timing of the real-time loop"), out.loop);
  declare_actuator(root.section("actuator", "facts about the actuator on the bench"), out.actuator);
  declare_driver(root.section("driver", "the device the loop reads and drives"), out.driver);
  declare_estimator(root.section("estimator", "the filtered least-squares estimator"),
                    out.estimator);
  declare_excitation(root.section("excitation", "the identification voltage"), out.excitation);
  declare_safety(root.section("safety", "limits that never depend on the estimator"), out.safety);
  declare_socket(root.section("socket", "the local JSON API"), out.socket);
  declare_state(root.section("state", "checkpoints of what the estimator learned"), out.state);
  Binder refine = root.section("refine", "the output-error refinement beside the paper's law");
  declare_refine(refine, out.refine);
  declare_refine_bench(refine, out.refine);
  declare_sensors(root.section("sensors", "what is known of the sensors"), out.refine);
  declare_health(root.section("health",
                              "actuator health: change and drift detection against a baseline "
                              "(docs/health.md)"),
                 out.health);
  declare_metrics(root.section("metrics",
                               "Prometheus metrics for node_exporter's textfile "
                               "collector (scp-estimatorctl metrics prints the same)"),
                  out.metrics);
  declare_recording(root.section("recording",
                                 "recording in service mode (a thread beside the "
                                 "loop; a full or slow disk drops rows, counted in "
                                 "STATUS, never stalls the loop)"),
                    out.recording);
  root.choice("log_level", out.log_level, "info", {"trace", "debug", "info", "warn", "error"},
              "least severe log level written to stderr (journald)");
}

DaemonConfig load_config_file(const std::string& path) {
  return load_node(parse_yaml(read_config_file(path), path), path);
}

DaemonConfig load_config_text(const std::string& text, const std::string& name) {
  return load_node(parse_yaml(text, name), name);
}

namespace {

// A '|' inside a cell would end it.
std::string cell(const std::string& text) {
  std::string out;
  for (const char c : text) {
    if (c == '|') out += '\\';
    out += c;
  }
  return out;
}

}  // namespace

std::string config_reference_markdown() {
  DaemonConfig defaults;
  Binder doc = Binder::documenting();
  declare_daemon_keys(doc, defaults);
  std::ostringstream out;
  out << "# Configuration reference\n\n"
      << "Generated by `scp-estimatord --print-config-reference`. Every key is optional; the\n"
      << "default applies when it is missing. Unknown keys are errors.\n\n"
      << "| key | type | default | allowed | meaning |\n|---|---|---|---|---|\n";
  for (const auto& key : doc.docs()) {
    if (key.type == "section") {
      out << "| **" << key.path << "** | section | | | " << key.doc << " |\n";
      continue;
    }
    out << "| `" << key.path << "` | " << cell(key.type) << " | " << cell(key.deflt) << " | "
        << cell(key.range) << " | " << cell(key.doc) << " |\n";
  }
  return out.str();
}

}  // namespace scp::config

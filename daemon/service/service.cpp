#include "daemon/service/service.hpp"

#include <pthread.h>
#include <signal.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <memory>
#include <thread>

#include "daemon/analysis/refine/refine_worker.hpp"
#include "daemon/config/config_file.hpp"
#include "daemon/core/excitation_exchange.hpp"
#include "daemon/core/loop.hpp"
#include "daemon/core/rt/alloc_hook.hpp"
#include "daemon/core/rt/loop_stats.hpp"
#include "daemon/core/rt/periodic_timer.hpp"
#include "daemon/core/rt/rt_setup.hpp"
#include "daemon/core/rt/sd_notify.hpp"
#include "daemon/outputs/log/journal_log.hpp"
#include "daemon/outputs/metrics/metrics_publisher.hpp"
#include "daemon/outputs/recording/recorder.hpp"
#include "daemon/outputs/server/api_server.hpp"
#include "daemon/programs/cli/program_info.hpp"
#include "daemon/service/driver_factory.hpp"
#include "daemon/service/event_log.hpp"
#include "daemon/service/reload.hpp"
#include "daemon/service/start_wait.hpp"
#include "daemon/service/state/checkpoint.hpp"
#include "daemon/service/state/state_directory.hpp"
#include "daemon/service/warm_start.hpp"

#ifndef SCP_RELEASE
#define SCP_RELEASE "0.1.0"
#endif

namespace scp::daemon {

namespace {

using Clock = std::chrono::steady_clock;

// Everything the loop thread needs, built before it starts so that the thread allocates nothing
// after its real-time set-up.
struct LoopThread {
  Loop& loop;
  rt::ServiceNotifier& notifier;
  const config::DaemonConfig& config;
  rt::LatencyHistogram& lateness;  // read by the server for STATUS
  std::atomic<bool> stop{false};
  std::atomic<bool> started{false};
  std::atomic<bool> setup_failed{false};
  std::vector<std::string> rt_warnings;  // written before `started`, read after
  std::string setup_error;

  void run() noexcept {
    const auto period = std::chrono::nanoseconds(
        static_cast<std::int64_t>(std::llround(config.loop.period_s * 1e9)));
    try {
      rt_warnings = rt::apply_rt_settings(config.loop.realtime);
    } catch (const std::exception& e) {
      setup_error = e.what();
      setup_failed.store(true, std::memory_order_release);
      return;
    }
    // period_s is validated to [1e-4, 1] s by the config, so the timer cannot refuse it.
    rt::PeriodicTimer timer(period);
    rt::LoopStatsAccumulator stats;
    stats.attach(&lateness);
    rt::WatchdogPacer pacer(notifier.watchdog_interval(), period);
    // From here on the thread must not allocate; the benchmark build counts it (alloc_hook.hpp).
    const std::int64_t allocations_at_start = rt::thread_allocation_count();
    timer.start();
    started.store(true, std::memory_order_release);
    while (!stop.load(std::memory_order_acquire)) {
      const rt::WakeResult wake = timer.wait_next();
      stats.record_wake(wake);
      LoopStatistics loop_stats = stats.snapshot();
      if (allocations_at_start >= 0) {
        loop_stats.allocations_counted = true;
        loop_stats.allocations =
            static_cast<std::uint64_t>(rt::thread_allocation_count() - allocations_at_start);
      }
      loop.set_loop_statistics(loop_stats);
      // The deadline's CLOCK_MONOTONIC time lets a driver stamp samples when they were taken.
      const drivers::CycleTime now{static_cast<double>(wake.cycle) * config.loop.period_s,
                                   config.loop.period_s, wake.deadline_ns};
      loop.cycle(now);
      stats.record_exec(timer.mark_cycle_end());
      // Only a loop that completes its cycles pets the watchdog: a stalled driver call or a
      // wedged loop stops the pings and systemd restarts the service.
      if (pacer.due(wake.cycle)) notifier.watchdog();
    }
    loop.shutdown();
  }
};

std::string checkpoint_path(const config::DaemonConfig& cfg) {
  return (std::filesystem::path(cfg.state.directory) / "estimator.state").string();
}

void save(const config::DaemonConfig& cfg, const EstimatorStateView& s, const std::string& driver) {
  if (!s.valid) return;  // nothing learned yet: keep the previous checkpoint
  try {
    state::save_checkpoint(checkpoint_path(cfg),
                           to_checkpoint(s, driver, cfg.actuator.name, driver_endpoint(cfg)));
    spdlog::debug("checkpoint written to {}", checkpoint_path(cfg));
  } catch (const std::exception& e) {
    spdlog::error("checkpoint failed, the previous one is kept: {}", e.what());
  }
}

// What a reload (SIGHUP, systemctl reload) may change in the running daemon, and how it reaches
// each thread without making the loop wait: safety limits through a seqlock, the excitation over
// the exchange's rings, the recording by a new recorder and the ring pointer the loop reads each
// cycle, the metrics and the log level on this (the main) thread.
struct Reloadable {
  const config::DaemonConfig& started;
  std::string started_text;  // the file at the start: restart-only keys are compared with it
  std::string applied_text;  // the last file applied: reloadable keys are compared with it
  SafetyCell& safety;
  ExcitationExchange& excitation;
  const rt::Seqlock<PublishedState>& published;
  std::unique_ptr<RecordRing>& record_ring;  // allocated once, when first recording
  std::atomic<RecordRing*>& live_ring;       // what the loop pushes to; null: not recording
  std::unique_ptr<Recorder>& recorder;
  MetricsPublisher& metrics;
};

std::string joined(const std::vector<std::string>& keys) {
  std::string out;
  for (const auto& key : keys) out += (out.empty() ? "" : ", ") + key;
  return out;
}

// Re-reads the configuration file. Everything that can fail (the file's validation, the new
// excitation, opening the new recording's first file) happens before anything is applied: a
// failure refuses the file whole, in one error line, and the running configuration stays.
void reload(Reloadable& r) {
  const std::string& source = r.started.source;
  if (source.empty()) {
    log::notice("SIGHUP: no configuration file to reload (running on defaults)");
    return;
  }
  ReloadPlan plan;
  std::unique_ptr<excitation::Excitation> next_excitation;
  std::unique_ptr<Recorder> next_recorder;
  const auto changed = [&plan](const std::string& key) {
    return std::find(plan.applied.begin(), plan.applied.end(), key) != plan.applied.end();
  };
  try {
    plan = plan_reload(source, r.started_text, r.applied_text);
    // excitation.enabled alone needs no new excitation, only the switch.
    const bool settings_changed =
        std::any_of(plan.applied.begin(), plan.applied.end(), [](const std::string& k) {
          return in_section(k, "excitation") && k != "excitation.enabled";
        });
    if (settings_changed) {
      next_excitation = std::make_unique<excitation::Excitation>(plan.fresh.excitation.settings);
      // Brought to the loop's present time here, so that the loop's first call does not step
      // a PRBS through hours of bits.
      next_excitation->voltage(r.published.load().uptime_s);
    }
    if (plan.recording && !plan.fresh.recording.directory.empty()) {
      if (!r.record_ring) r.record_ring = std::make_unique<RecordRing>();
      next_recorder =
          std::make_unique<Recorder>(plan.fresh.recording, r.started.actuator.name, *r.record_ring);
    }
  } catch (const std::exception& e) {
    spdlog::error("SIGHUP: {} refused, the running configuration is kept: {}", source, e.what());
    return;
  }

  log::set_level(log::parse_level(plan.fresh.log_level).value_or(spdlog::level::info));
  if (plan.safety) r.safety.store(plan.fresh.safety);
  bool complete = true;  // else the next SIGHUP compares with the file applied before this one
  if (plan.excitation) {
    const std::int8_t enabled =
        changed("excitation.enabled") ? (plan.fresh.excitation.enabled ? 1 : 0) : -1;
    if (!r.excitation.offer(std::move(next_excitation), enabled)) {
      complete = false;
      spdlog::warn(
          "SIGHUP: the loop has not taken the previous excitation yet; excitation.* "
          "not applied, send SIGHUP again");
    }
  }
  if (plan.recording) {
    std::uint64_t marked = r.published.load().record_dropped;
    if (r.recorder) {
      // Stopping: the loop stops pushing first. Switching: rows wait in the ring meanwhile.
      if (!next_recorder) r.live_ring.store(nullptr, std::memory_order_release);
      try {
        r.recorder->finish();
      } catch (const std::exception& e) {
        spdlog::error("recording: {}", e.what());
      }
      marked = r.recorder->dropped_marked();
      log::notice("recording: {} closed ({} rows written)", r.recorder->current_file(),
                  r.recorder->rows_written());
      r.recorder.reset();
    }
    if (next_recorder) {
      next_recorder->start(marked);
      r.recorder = std::move(next_recorder);
      r.live_ring.store(r.record_ring.get(), std::memory_order_release);
      log::notice("recording to {} (a new file every {} MiB or {} s, keeping {}, compress {})",
                  r.recorder->current_file(), plan.fresh.recording.rotate_size_mib,
                  plan.fresh.recording.rotate_interval_s, plan.fresh.recording.keep_files,
                  plan.fresh.recording.compress);
    }
  }
  if (plan.metrics) r.metrics.apply(plan.fresh.metrics);
  if (complete) r.applied_text = plan.text;

  log::notice(
      "SIGHUP: reloaded {}: applied {} (log_level {}, safety limits: voltage_max_v {} V, "
      "temperature {} .. {} °C)",
      source, plan.applied.empty() ? "nothing changed" : joined(plan.applied), plan.fresh.log_level,
      plan.fresh.safety.voltage_max_v, plan.fresh.safety.temperature_min_c,
      plan.fresh.safety.temperature_max_c);
  if (!plan.restart.empty()) {
    spdlog::warn(
        "SIGHUP: changed in {} but not applied, a restart is needed (systemctl restart): {}",
        source, joined(plan.restart));
  }
}

}  // namespace

int run_service(const config::DaemonConfig& cfg) {
  // Under systemd stderr is journald's stream: priorities as prefixes, no time stamps.
  log::setup(log::parse_level(cfg.log_level).value_or(spdlog::level::info),
             log::stream_is_journal(std::getenv("JOURNAL_STREAM"), STDERR_FILENO));

  // Signals are taken synchronously by this thread only; every other thread inherits the mask.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  // A client vanishing mid-reply must not kill the daemon (and skip the 0 V of shutdown).
  std::signal(SIGPIPE, SIG_IGN);

  // Everything that can refuse the start is checked before the device is opened: a second
  // daemon, or one with a missing socket or state directory, must not write into a running
  // bench's command stream on its way out.
  state::check_state_directory(cfg.state.directory);
  const state::StateLock state_lock(
      cfg.state.directory, "actuator " + cfg.actuator.name + ", socket " + cfg.socket.path +
                               (cfg.source.empty() ? "" : ", config " + cfg.source));
  auto driver = make_driver(cfg);
  const std::string driver_name(driver->name());

  // Before any thread starts: small locked stacks instead of 8 MiB each (rt_setup.hpp).
  if (!rt::set_default_thread_stack(rt::kThreadStackBytes)) {
    spdlog::warn("could not set the threads' stack size to {} KiB; they keep the default",
                 rt::kThreadStackBytes >> 10);
  }
  auto published = std::make_unique<rt::Seqlock<PublishedState>>();
  auto commands = std::make_unique<CommandRing>();
  auto lateness = std::make_unique<rt::LatencyHistogram>();
  // The refinement: the loop hands its samples over a ring to a worker thread below it.
  std::unique_ptr<refine::HandOffRing> handoff;
  std::unique_ptr<rt::Seqlock<refine::RefinedView>> refined;
  std::unique_ptr<refine::RefineWorker> refine_worker;
  if (cfg.refine.enabled) {
    handoff = std::make_unique<refine::HandOffRing>();
    refined = std::make_unique<rt::Seqlock<refine::RefinedView>>();
    refine_worker = std::make_unique<refine::RefineWorker>(cfg, *handoff, *published, *refined);
  }
  // Recording: the loop pushes rows into a ring (dropping and counting them when it is full), a
  // thread writes them to rotating files. The loop reads which ring each cycle (`live_ring`), so
  // that a reload can start, switch or stop the recording.
  std::unique_ptr<RecordRing> record_ring;
  std::unique_ptr<Recorder> recorder;
  std::atomic<RecordRing*> live_ring{nullptr};
  if (!cfg.recording.directory.empty()) {
    record_ring = std::make_unique<RecordRing>();
    recorder = std::make_unique<Recorder>(cfg.recording, cfg.actuator.name, *record_ring);
    recorder->start();
    live_ring.store(record_ring.get());
    spdlog::info("recording to {} (a new file every {} MiB or {} s, keeping {}, compress {})",
                 recorder->current_file(), cfg.recording.rotate_size_mib,
                 cfg.recording.rotate_interval_s, cfg.recording.keep_files, cfg.recording.compress);
  }
  // Outlives the loop: it owns the excitations a reload hands over.
  auto excitation_exchange = std::make_unique<ExcitationExchange>();
  auto loop = std::make_unique<Loop>(cfg, *driver, *published, *commands, nullptr,
                                     /*block_when_record_full=*/false, handoff.get());
  loop->follow_recording(&live_ring);
  loop->follow_excitation(excitation_exchange.get());
  auto safety_cell = std::make_unique<SafetyCell>();
  safety_cell->store(cfg.safety);
  loop->follow_safety(safety_cell.get());

  if (cfg.state.warm_start) {
    std::string warning;
    if (auto checkpoint = state::load_checkpoint(checkpoint_path(cfg), warning)) {
      std::string why;
      if (!checkpoint_fits(*checkpoint, cfg, driver_name, why)) {
        spdlog::warn("refusing checkpoint {}: {}; starting cold", checkpoint_path(cfg), why);
      } else if (loop->restore(to_state(to_view(*checkpoint)))) {
        spdlog::info("warm start from {} (saved at loop time {:.1f} s)", checkpoint_path(cfg),
                     checkpoint->t);
      } else {
        spdlog::warn("{}: unusable estimator state; starting cold", checkpoint_path(cfg));
      }
    } else if (!warning.empty()) {
      spdlog::warn("{}", warning);
    }
  }
  // Clients that connect before the first cycle see the restored θ̂, not zeros.
  loop->publish_initial();
  // From the state before the first cycle, so that the first change (to running) is logged too.
  EventLog events(published->load());

  server::ServerSettings server_settings;
  server_settings.socket_path = cfg.socket.path;
  server_settings.group = cfg.socket.group;
  server_settings.mode = cfg.socket.mode;
  server_settings.max_clients = static_cast<std::size_t>(cfg.socket.max_clients);
  server_settings.max_line = static_cast<std::size_t>(cfg.socket.max_line_bytes);
  server_settings.idle_timeout_s = cfg.socket.idle_timeout_s;
  const server::ServerInfo server_info{SCP_RELEASE, driver_name, cfg.source, cfg.actuator.name};
  server::ApiServer server(server_settings, server_info, *published, *commands, refined.get(),
                           lateness.get());
  MetricsPublisher metrics(cfg, server_info, *published, refined.get());
  // Reload: the file as started (to name what changed) and what a reload changes.
  const std::string config_text = cfg.source.empty() ? "" : config::read_config_file(cfg.source);
  Reloadable reloadable{cfg,        config_text, config_text, *safety_cell, *excitation_exchange,
                        *published, record_ring, live_ring,   recorder,     metrics};
  server.start();
  spdlog::info("listening on {}", cfg.socket.path);

  // driver.start_timeout_s counts from here: a device absent or slow at start is awaited.
  const auto opened_at = Clock::now();
  StartWait start_wait(cfg.driver.start_timeout_s, driver_endpoint(cfg));
  driver->open();
  spdlog::info("scp-estimatord {} starting: driver {}, period {} s, config {}", SCP_RELEASE,
               driver_name, cfg.loop.period_s, cfg.source);
  if (!driver->stats().link_up) {
    spdlog::info(
        "driver {}: the device does not answer yet ({}); output 0 V not confirmed, retrying in "
        "the background ({})",
        driver_name, driver->background_error(),
        cfg.driver.start_timeout_s > 0.0
            ? "for driver.start_timeout_s = " + std::to_string(cfg.driver.start_timeout_s) + " s"
            : std::string("without limit: driver.start_timeout_s is 0"));
  }

  rt::ServiceNotifier notifier = rt::ServiceNotifier::from_environment();
  if (!notifier.problem().empty()) spdlog::warn("systemd notification: {}", notifier.problem());

  LoopThread body{*loop, notifier, cfg, *lateness, {}, {}, {}, {}, {}};
  // The loop's larger stack, then the small default again for threads started later.
  const bool loop_stack_set = rt::set_default_thread_stack(rt::kLoopThreadStackBytes);
  std::thread loop_thread([&body] { body.run(); });
  if (loop_stack_set) rt::set_default_thread_stack(rt::kThreadStackBytes);
  // Whatever way this function is left (an exception included), the loop stops and the output
  // goes to 0 V before the driver is destroyed.
  struct StopGuard {
    LoopThread& body;
    std::thread& thread;
    drivers::Driver& driver;
    ~StopGuard() {
      body.stop.store(true, std::memory_order_release);
      if (thread.joinable()) thread.join();
      driver.safe_state();
    }
  } stop_guard{body, loop_thread, *driver};

  // Wait for the loop to publish its first cycle before telling systemd we are ready.
  while (!body.started.load(std::memory_order_acquire) &&
         !body.setup_failed.load(std::memory_order_acquire)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  if (body.setup_failed.load()) {
    loop_thread.join();
    spdlog::critical("real-time set-up failed (loop.realtime.required is true): {}",
                     body.setup_error);
    driver->safe_state();
    driver->close();
    server.stop();
    return 1;
  }
  for (const auto& warning : body.rt_warnings) spdlog::warn("{}", warning);
  if (refine_worker) {
    refine_worker->start();
    spdlog::info("refinement: a fit of the last {} s every {} s once {} s of data are in",
                 cfg.refine.window_s, cfg.refine.interval_s, cfg.refine.min_window_s);
  }
  // publish_initial() was version 1: wait for the loop's own first cycles.
  while (published->version() < 3) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  notifier.ready();
  notifier.status("running");
  spdlog::info("loop running");

  std::uint64_t last_overruns = 0;
  auto last_overrun_log = Clock::now() - std::chrono::hours(1);
  auto last_checkpoint = Clock::now();
  int exit_code = 0;
  const auto since_open = [&opened_at] {
    return std::chrono::duration<double>(Clock::now() - opened_at).count();
  };
  for (;;) {
    const double nap_s = start_wait.sleep_s(since_open(), 0.2);
    timespec wait{0, static_cast<long>(nap_s * 1e9)};
    const int signal = sigtimedwait(&signals, nullptr, &wait);
    if (signal == SIGTERM || signal == SIGINT) {
      spdlog::info("{} received: stopping", strsignal(signal));
      break;
    }
    if (signal == SIGHUP) reload(reloadable);
    excitation_exchange->collect();

    const PublishedState now = published->load();
    if (const auto status = events.observe(now, *driver)) notifier.status(*status);
    if (start_wait.observe(now, since_open()) == StartWait::Verdict::timed_out) {
      spdlog::critical("{}", start_wait.timeout_message());
      notifier.status("device did not answer within driver.start_timeout_s");
      exit_code = cli::kExitUnavailable;
      break;
    }
    // Overrun warnings are rate-limited so a struggling machine does not flood the journal.
    if (now.loop.overruns > last_overruns &&
        Clock::now() - last_overrun_log >
            std::chrono::duration<double>(cfg.loop.overrun_warning_interval_s)) {
      spdlog::warn(
          "{} loop overruns ({} periods skipped) so far; lateness max {:.0f} µs, p99 "
          "{:.0f} µs",
          now.loop.overruns, now.loop.missed_periods, now.loop.lateness_max_us,
          now.loop.lateness_p99_us);
      last_overruns = now.loop.overruns;
      last_overrun_log = Clock::now();
    }
    metrics.poll(Clock::now());
    if (Clock::now() - last_checkpoint >
        std::chrono::duration<double>(cfg.state.checkpoint_interval_s)) {
      save(cfg, loop->estimator_state().load(), driver_name);
      last_checkpoint = Clock::now();
    }
  }

  notifier.stopping();
  body.stop.store(true, std::memory_order_release);
  loop_thread.join();  // the loop's last act is 0 V (Loop::shutdown)
  driver->safe_state();
  if (refine_worker) refine_worker->stop();  // waits for a fit in progress
  save(cfg, to_view(loop->estimator().state()), driver_name);
  if (recorder) {
    try {
      recorder->finish();
    } catch (const std::exception& e) {
      spdlog::error("recording: {}", e.what());
    }
    spdlog::info("recording: {} rows written, {} dropped by the loop, {} lost to write errors",
                 recorder->rows_written(), loop->dropped_record_rows(), recorder->rows_failed());
  }
  server.stop();
  driver->close();
  const drivers::DriverStats final_stats = driver->stats();
  if (final_stats.output_confirmed && final_stats.output_v == 0.0) {
    spdlog::info("stopped; output at 0 V");
  } else if (final_stats.reads == 0 && final_stats.writes == 0 && final_stats.output_v == 0.0) {
    spdlog::info("stopped; the device never answered, so no command reached it");
  } else {
    spdlog::error(
        "stopped; {}: the device did not acknowledge 0 V and may still drive the actuator; only "
        "its own communication watchdog can bring it to 0 V (docs/driver-modbus.md)",
        output_text(final_stats));
  }
  return exit_code;
}

}  // namespace scp::daemon

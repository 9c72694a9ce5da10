#include "daemon/service.hpp"

#include <pthread.h>
#include <signal.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <memory>
#include <thread>

#include "daemon/driver_factory.hpp"
#include "daemon/loop.hpp"
#include "daemon/rt/alloc_hook.hpp"
#include "daemon/rt/loop_stats.hpp"
#include "daemon/rt/periodic_timer.hpp"
#include "daemon/rt/rt_setup.hpp"
#include "daemon/rt/sd_notify.hpp"
#include "daemon/server/api_server.hpp"
#include "daemon/state/checkpoint.hpp"

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
      const drivers::CycleTime now{static_cast<double>(wake.cycle) * config.loop.period_s,
                                   config.loop.period_s};
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
    state::save_checkpoint(checkpoint_path(cfg), to_checkpoint(s, driver));
    spdlog::debug("checkpoint written to {}", checkpoint_path(cfg));
  } catch (const std::exception& e) {
    spdlog::error("checkpoint failed, the previous one is kept: {}", e.what());
  }
}

}  // namespace

int run_service(const config::DaemonConfig& cfg) {
  auto logger = spdlog::stderr_color_mt("scp-estimatord");
  spdlog::set_default_logger(logger);
  // journald adds its own time stamps; keep the line short.
  spdlog::set_pattern("%^%l%$: %v");
  spdlog::set_level(spdlog::level::from_str(cfg.log_level));

  // Signals are taken synchronously by this thread only; every other thread inherits the mask.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  auto driver = make_driver(cfg);
  driver->open();
  const std::string driver_name(driver->name());
  spdlog::info("scp-estimatord {} starting: driver {}, period {} s, config {}", SCP_RELEASE,
               driver_name, cfg.loop.period_s, cfg.source);

  auto published = std::make_unique<rt::Seqlock<PublishedState>>();
  auto commands = std::make_unique<CommandRing>();
  auto loop = std::make_unique<Loop>(cfg, *driver, *published, *commands, nullptr, false);

  if (cfg.state.warm_start) {
    std::string warning;
    if (auto checkpoint = state::load_checkpoint(checkpoint_path(cfg), warning)) {
      if (loop->restore(to_state(to_view(*checkpoint)))) {
        spdlog::info("warm start from {} (saved at loop time {:.1f} s)", checkpoint_path(cfg),
                     checkpoint->t);
      } else {
        spdlog::warn("{}: unusable estimator state; starting cold", checkpoint_path(cfg));
      }
    } else if (!warning.empty()) {
      spdlog::warn("{}", warning);
    }
  }

  server::ServerSettings server_settings;
  server_settings.socket_path = cfg.socket.path;
  server_settings.group = cfg.socket.group;
  server_settings.mode = cfg.socket.mode;
  server_settings.max_clients = static_cast<std::size_t>(cfg.socket.max_clients);
  server_settings.max_line = static_cast<std::size_t>(cfg.socket.max_line_bytes);
  server_settings.idle_timeout_s = cfg.socket.idle_timeout_s;
  server::ApiServer server(server_settings, {SCP_RELEASE, driver_name, cfg.source}, *published,
                           *commands);
  server.start();
  spdlog::info("listening on {}", cfg.socket.path);

  rt::ServiceNotifier notifier = rt::ServiceNotifier::from_environment();
  if (!notifier.problem().empty()) spdlog::warn("systemd notification: {}", notifier.problem());

  LoopThread body{*loop, notifier, cfg, {}, {}, {}, {}, {}};
  std::thread loop_thread([&body] { body.run(); });
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
  while (published->version() < 2) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  notifier.ready();
  notifier.status("running");
  spdlog::info("loop running");

  RunState last_state = RunState::starting;
  std::uint64_t last_overruns = 0;
  auto last_overrun_log = Clock::now() - std::chrono::hours(1);
  auto last_checkpoint = Clock::now();
  int exit_code = 0;
  for (;;) {
    timespec wait{0, 200'000'000};
    const int signal = sigtimedwait(&signals, nullptr, &wait);
    if (signal == SIGTERM || signal == SIGINT) {
      spdlog::info("{} received: stopping", strsignal(signal));
      break;
    }
    if (signal == SIGHUP) spdlog::info("SIGHUP ignored: restart the service to reload the config");

    const PublishedState now = published->load();
    if (now.state != last_state) {
      if (now.state == RunState::fault) {
        spdlog::error("FAULT, output at 0 V: {}", now.fault_reason.data());
        notifier.status(std::string("FAULT: ") + now.fault_reason.data());
      } else {
        spdlog::info("state {}", to_string(now.state));
        notifier.status(to_string(now.state));
      }
      last_state = now.state;
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
  save(cfg, to_view(loop->estimator().state()), driver_name);
  server.stop();
  driver->close();
  spdlog::info("stopped; output at 0 V");
  return exit_code;
}

}  // namespace scp::daemon

#include "daemon/service/service.hpp"

#include <pthread.h>
#include <signal.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <optional>
#include <thread>

#include "daemon/analysis/refine/refine_worker.hpp"
#include "daemon/core/excitation_exchange.hpp"
#include "daemon/core/loop.hpp"
#include "daemon/core/loop_thread.hpp"
#include "daemon/core/rt/rt_setup.hpp"
#include "daemon/core/rt/sd_notify.hpp"
#include "daemon/outputs/log/journal_log.hpp"
#include "daemon/outputs/metrics/metrics_publisher.hpp"
#include "daemon/outputs/server/api_server.hpp"
#include "daemon/programs/cli/program_info.hpp"
#include "daemon/service/checkpoints.hpp"
#include "daemon/service/driver_factory.hpp"
#include "daemon/service/event_log.hpp"
#include "daemon/service/health_service.hpp"
#include "daemon/service/recording_control.hpp"
#include "daemon/service/reloader.hpp"
#include "daemon/service/start_wait.hpp"
#include "daemon/service/state/state_directory.hpp"
#include "daemon/service/warm_start.hpp"

#ifndef SCP_RELEASE
#define SCP_RELEASE "0.1.0"
#endif

namespace scp::daemon {

namespace {

using Clock = std::chrono::steady_clock;

double seconds_between(Clock::time_point from, Clock::time_point to) {
  return std::chrono::duration<double>(to - from).count();
}

// Under systemd stderr is journald's stream: priorities as prefixes, no time stamps.
void start_logging(const config::DaemonConfig& cfg) {
  log::setup(log::parse_level(cfg.log_level).value_or(spdlog::level::info),
             log::stream_is_journal(std::getenv("JOURNAL_STREAM"), STDERR_FILENO));
}

// Signals are taken synchronously by the main thread only; every thread started later inherits
// the mask. A client vanishing mid-reply must not kill the daemon (and skip the 0 V of shutdown).
sigset_t take_signals() {
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  std::signal(SIGPIPE, SIG_IGN);
  return signals;
}

// The refinement: the loop hands its samples over a ring to a worker thread below it.
// The actuator's health monitor runs on the same worker, fed by the refinement.
struct Refinement {
  Refinement(const config::DaemonConfig& cfg, const rt::Seqlock<PublishedState>& published,
             const std::string& driver_name)
      : handoff(std::make_unique<HandOffRing>()),
        refined(std::make_unique<rt::Seqlock<refine::RefinedView>>()),
        health(std::make_unique<HealthService>(cfg, driver_name)),
        worker(cfg, *handoff, published, *refined, &health->agent()) {}
  std::unique_ptr<HandOffRing> handoff;
  std::unique_ptr<rt::Seqlock<refine::RefinedView>> refined;
  std::unique_ptr<HealthService> health;
  refine::RefineWorker worker;
};

// The daemon from start to stop. The members are declared in the order they are built; whatever
// way run() is left (an exception included), the destructor stops the loop and puts the output
// to 0 V before the driver is destroyed.
class Service {
 public:
  explicit Service(const config::DaemonConfig& cfg);
  ~Service();
  Service(const Service&) = delete;
  Service& operator=(const Service&) = delete;

  int run(const sigset_t& signals);

 private:
  void build_loop();
  void start_server();
  void open_device();
  bool start_loop();
  int watch(const sigset_t& signals);
  void warn_overruns(const PublishedState& now);
  void checkpoint_when_due();
  void shut_down();
  void log_final_output() const;
  double since_open() const { return seconds_between(opened_at_, Clock::now()); }

  config::DaemonConfig cfg_;  // a copy: refine.voltage_interval is resolved once the driver is made
  std::optional<state::StateLock> state_lock_;
  std::unique_ptr<drivers::Driver> driver_;
  std::string driver_name_;
  // Heap-allocated before any thread starts: the loop thread allocates nothing after its set-up.
  std::unique_ptr<rt::Seqlock<PublishedState>> published_;
  std::unique_ptr<CommandRing> commands_;
  std::unique_ptr<rt::LatencyHistogram> lateness_;
  std::unique_ptr<SafetyCell> safety_;
  // Outlives the loop: it owns the excitations a reload hands over.
  std::unique_ptr<ExcitationExchange> excitation_;
  std::unique_ptr<Refinement> refinement_;  // null: refine.enabled is false
  std::unique_ptr<RecordingControl> recording_;
  std::unique_ptr<Loop> loop_;
  std::unique_ptr<server::ApiServer> server_;
  std::unique_ptr<MetricsPublisher> metrics_;
  std::unique_ptr<Reloader> reloader_;
  std::optional<EventLog> events_;
  rt::ServiceNotifier notifier_;
  std::unique_ptr<LoopThread> loop_thread_;
  Clock::time_point opened_at_;
  Clock::time_point last_checkpoint_;
  std::uint64_t last_overruns_ = 0;
  Clock::time_point last_overrun_log_;
};

Service::Service(const config::DaemonConfig& cfg) : cfg_(cfg) {
  // Everything that can refuse the start is checked before the device is opened: a second
  // daemon, or one with a missing socket or state directory, must not write into a running
  // bench's command stream on its way out.
  state::check_state_directory(cfg.state.directory);
  state_lock_.emplace(cfg.state.directory,
                      "actuator " + cfg.actuator.name + ", socket " + cfg.socket.socket_path +
                          (cfg.source.empty() ? "" : ", config " + cfg.source));
  driver_ = make_driver(cfg);
  driver_name_ = std::string(driver_->name());
  config::resolve_voltage_interval(cfg_.refine, driver_->stamps_voltage_instants());
  // Before any thread starts: small locked stacks instead of 8 MiB each (rt_setup.hpp).
  if (!rt::set_default_thread_stack(rt::kThreadStackBytes)) {
    spdlog::warn("could not set the threads' stack size to {} KiB; they keep the default",
                 rt::kThreadStackBytes >> 10);
  }
  build_loop();
  warm_start(cfg, *loop_, driver_name_);
  // Clients that connect before the first cycle see the restored θ̂, not zeros.
  loop_->publish_initial();
  // From the state before the first cycle, so that the first change (to running) is logged too.
  events_.emplace(published_->load());
}

Service::~Service() {
  if (loop_thread_) loop_thread_->stop();  // the loop's last act is 0 V (Loop::shutdown)
  if (driver_) driver_->safe_state();
}

void Service::build_loop() {
  published_ = std::make_unique<rt::Seqlock<PublishedState>>();
  commands_ = std::make_unique<CommandRing>();
  lateness_ = std::make_unique<rt::LatencyHistogram>();
  safety_ = std::make_unique<SafetyCell>();
  safety_->store(cfg_.safety);
  excitation_ = std::make_unique<ExcitationExchange>();
  if (cfg_.refine.enabled)
    refinement_ = std::make_unique<Refinement>(cfg_, *published_, driver_name_);
  // The loop pushes rows into a ring (dropping and counting them when it is full), a thread writes
  // them to rotating files; the loop reads which ring each cycle, so a reload can switch it.
  recording_ = std::make_unique<RecordingControl>(cfg_.recording, cfg_.actuator.name);
  loop_ = std::make_unique<Loop>(cfg_, *driver_, *published_, *commands_, nullptr,
                                 /*block_when_record_full=*/false,
                                 refinement_ ? refinement_->handoff.get() : nullptr);
  loop_->follow_recording(recording_->live());
  loop_->follow_excitation(excitation_.get());
  loop_->follow_safety(safety_.get());
}

void Service::start_server() {
  const server::ServerInfo info{SCP_RELEASE, driver_name_, cfg_.source, cfg_.actuator.name};
  const rt::Seqlock<refine::RefinedView>* refined =
      refinement_ ? refinement_->refined.get() : nullptr;
  server_ = std::make_unique<server::ApiServer>(cfg_.socket, info, *published_, *commands_, refined,
                                                lateness_.get());
  if (refinement_) server_->set_health(refinement_->health.get());
  metrics_ = std::make_unique<MetricsPublisher>(cfg_, info, *published_, refined);
  reloader_ =
      std::make_unique<Reloader>(cfg_, *safety_, *excitation_, *published_, *recording_, *metrics_);
  server_->start();
  spdlog::info("listening on {}", cfg_.socket.socket_path);
}

// driver.start_timeout_s counts from here: a device absent or slow at start is awaited.
void Service::open_device() {
  opened_at_ = Clock::now();
  driver_->open();
  spdlog::info("scp-estimatord {} starting: driver {}, period {} s, config {}", SCP_RELEASE,
               driver_name_, cfg_.loop.period_s, cfg_.source);
  if (driver_->stats().link_up) return;
  spdlog::info(
      "driver {}: the device does not answer yet ({}); output 0 V not confirmed, retrying in the "
      "background ({})",
      driver_name_, driver_->background_error(),
      cfg_.driver.start_timeout_s > 0.0
          ? "for driver.start_timeout_s = " + std::to_string(cfg_.driver.start_timeout_s) + " s"
          : std::string("without limit: driver.start_timeout_s is 0"));
}

// False when the real-time set-up failed (loop.realtime.required).
bool Service::start_loop() {
  notifier_ = rt::ServiceNotifier::from_environment();
  if (!notifier_.problem().empty()) spdlog::warn("systemd notification: {}", notifier_.problem());
  loop_thread_ = std::make_unique<LoopThread>(*loop_, cfg_.loop, notifier_, *lateness_);
  if (!loop_thread_->start()) {
    spdlog::critical("real-time set-up failed (loop.realtime.required is true): {}",
                     loop_thread_->setup_error());
    driver_->safe_state();
    driver_->close();
    server_->stop();
    return false;
  }
  for (const auto& warning : loop_thread_->warnings()) spdlog::warn("{}", warning);
  if (refinement_) {
    refinement_->worker.start();
    spdlog::info("refinement: a fit of the last {} s every {} s once {} s of data are in",
                 cfg_.refine.window_s, cfg_.refine.interval_s, cfg_.refine.min_window_s);
  }
  // publish_initial() was version 1: wait for the loop's own first cycles before telling
  // systemd the service is ready.
  while (published_->version() < 3) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  notifier_.ready();
  notifier_.status("running");
  spdlog::info("loop running");
  return true;
}

int Service::run(const sigset_t& signals) {
  start_server();
  open_device();
  if (!start_loop()) return 1;
  const int exit_code = watch(signals);
  shut_down();
  return exit_code;
}

// The main thread's watch until a signal stops it: reloads, the journal's account of the loop,
// the start timeout, overruns, metrics and checkpoints. Returns the exit code.
int Service::watch(const sigset_t& signals) {
  StartWait start_wait(cfg_.driver.start_timeout_s, driver_endpoint(cfg_));
  last_checkpoint_ = Clock::now();
  last_overrun_log_ = Clock::now() - std::chrono::hours(1);
  for (;;) {
    const double nap_s = start_wait.sleep_s(since_open(), 0.2);
    const timespec wait{0, static_cast<long>(nap_s * 1e9)};
    const int signal = sigtimedwait(&signals, nullptr, &wait);
    if (signal == SIGTERM || signal == SIGINT) {
      spdlog::info("{} received: stopping", strsignal(signal));
      return 0;
    }
    if (signal == SIGHUP) reloader_->reload();
    excitation_->collect();

    const PublishedState now = published_->load();
    if (const auto status = events_->observe(now, *driver_)) notifier_.status(*status);
    if (start_wait.observe(now, since_open()) == StartWait::Verdict::timed_out) {
      spdlog::critical("{}", start_wait.timeout_message());
      notifier_.status("device did not answer within driver.start_timeout_s");
      return cli::kExitUnavailable;
    }
    warn_overruns(now);
    metrics_->poll(Clock::now());
    checkpoint_when_due();
  }
}

// Rate-limited, so that a struggling machine does not flood the journal.
void Service::warn_overruns(const PublishedState& now) {
  if (now.loop.overruns <= last_overruns_ ||
      seconds_between(last_overrun_log_, Clock::now()) <= cfg_.loop.overrun_warning_interval_s) {
    return;
  }
  spdlog::warn(
      "{} loop overruns ({} periods skipped) so far; lateness max {:.0f} µs, p99 {:.0f} µs",
      now.loop.overruns, now.loop.missed_periods, now.loop.lateness_max_us,
      now.loop.lateness_p99_us);
  last_overruns_ = now.loop.overruns;
  last_overrun_log_ = Clock::now();
}

void Service::checkpoint_when_due() {
  if (seconds_between(last_checkpoint_, Clock::now()) <= cfg_.state.checkpoint_interval_s) return;
  save_checkpoint(cfg_, loop_->estimator_state().load(), driver_name_);
  last_checkpoint_ = Clock::now();
}

void Service::shut_down() {
  notifier_.stopping();
  loop_thread_->stop();  // the loop's last act is 0 V (Loop::shutdown)
  driver_->safe_state();
  if (refinement_) refinement_->worker.stop();  // waits for a fit in progress
  save_checkpoint(cfg_, to_view(loop_->estimator().state()), driver_name_);
  recording_->finish(loop_->dropped_record_rows());
  server_->stop();
  driver_->close();
  log_final_output();
}

void Service::log_final_output() const {
  const drivers::DriverStats final_stats = driver_->stats();
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
}

}  // namespace

int run_service(const config::DaemonConfig& cfg) {
  start_logging(cfg);
  const sigset_t signals = take_signals();
  Service service(cfg);
  return service.run(signals);
}

}  // namespace scp::daemon

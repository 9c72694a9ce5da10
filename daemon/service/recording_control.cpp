#include "daemon/service/recording_control.hpp"

#include <spdlog/spdlog.h>

#include "daemon/outputs/log/journal_log.hpp"

namespace scp::daemon {

namespace {

std::string rotation_text(const config::RecordingSettings& s) {
  return fmt::format("a new file every {} MiB or {} s, keeping {}, compress {}", s.rotate_size_mib,
                     s.rotate_interval_s, s.keep_files, config::to_string(s.compress));
}

void finish_logged(Recorder& recorder) {
  try {
    recorder.finish();
  } catch (const std::exception& e) {
    spdlog::error("recording: {}", e.what());
  }
}

}  // namespace

RecordingControl::RecordingControl(const config::RecordingSettings& settings, std::string actuator)
    : actuator_(std::move(actuator)) {
  if (settings.directory.empty()) return;
  ring_ = std::make_unique<RecordRing>();
  recorder_ = std::make_unique<Recorder>(settings, actuator_, *ring_);
  recorder_->start();
  live_.store(ring_.get());
  spdlog::info("recording to {} ({})", recorder_->current_file(), rotation_text(settings));
}

std::unique_ptr<Recorder> RecordingControl::prepare(const config::RecordingSettings& settings) {
  if (settings.directory.empty()) return nullptr;
  if (!ring_) ring_ = std::make_unique<RecordRing>();
  return std::make_unique<Recorder>(settings, actuator_, *ring_);
}

void RecordingControl::switch_to(std::unique_ptr<Recorder> next,
                                 const config::RecordingSettings& settings,
                                 std::uint64_t loop_dropped) {
  std::uint64_t marked = loop_dropped;
  if (recorder_) {
    // Stopping: the loop stops pushing first. Switching: rows wait in the ring meanwhile.
    if (!next) live_.store(nullptr, std::memory_order_release);
    finish_logged(*recorder_);
    marked = recorder_->dropped_marked();
    log::notice("recording: {} closed ({} rows written)", recorder_->current_file(),
                recorder_->rows_written());
    recorder_.reset();
  }
  if (!next) return;
  next->start(marked);
  recorder_ = std::move(next);
  live_.store(ring_.get(), std::memory_order_release);
  log::notice("recording to {} ({})", recorder_->current_file(), rotation_text(settings));
}

void RecordingControl::finish(std::uint64_t loop_dropped) {
  if (!recorder_) return;
  finish_logged(*recorder_);
  spdlog::info("recording: {} rows written, {} dropped by the loop, {} lost to write errors",
               recorder_->rows_written(), loop_dropped, recorder_->rows_failed());
}

}  // namespace scp::daemon

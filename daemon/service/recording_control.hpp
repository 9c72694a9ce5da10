#pragma once
// The recording of a running service: started from the configuration, then started, switched to
// new settings or stopped by a reload while the loop runs, and finished at shutdown. The loop
// reads which ring to push to at each cycle (live()), so switching never makes it wait: rows wait
// in the ring while one recorder hands over to the next.

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

#include "daemon/config/daemon_config.hpp"
#include "daemon/core/loop.hpp"
#include "daemon/outputs/recording/recorder.hpp"

namespace scp::daemon {

class RecordingControl {
 public:
  // Starts recording when settings.directory is set (throws std::runtime_error naming the
  // directory when the first file cannot be opened).
  RecordingControl(const config::RecordingSettings& settings, std::string actuator);

  // What the loop follows (Loop::follow_recording): the ring to push to, null when not recording.
  const std::atomic<RecordRing*>* live() const noexcept { return &live_; }

  // A reload, first half: the recorder for `settings`, its first file open, not yet draining; null
  // when the new settings record nothing. Throws (and nothing changes) when the file cannot be
  // opened.
  std::unique_ptr<Recorder> prepare(const config::RecordingSettings& settings);
  // Second half: the current recorder finishes, `next` (may be null: stop) takes over the ring.
  // `loop_dropped` is the loop's dropped-row count now (PublishedState::record_dropped).
  void switch_to(std::unique_ptr<Recorder> next, const config::RecordingSettings& settings,
                 std::uint64_t loop_dropped);

  // Shutdown, after the loop has stopped: drains, closes and logs what was written.
  void finish(std::uint64_t loop_dropped);

 private:
  std::string actuator_;
  std::unique_ptr<RecordRing> ring_;  // allocated once, when first recording
  std::atomic<RecordRing*> live_{nullptr};
  std::unique_ptr<Recorder> recorder_;
};

}  // namespace scp::daemon

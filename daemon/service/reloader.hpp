#pragma once
// A reload (SIGHUP, systemctl reload) applied to the running daemon without making the loop wait:
// the safety limits through a seqlock, the excitation over the exchange's rings, the recording by
// a new recorder on the ring the loop reads each cycle, the metrics and the log level on the main
// thread. Which keys changed and which of them apply is reload.hpp's plan; everything that can
// fail (the file's validation, the new excitation, the new recording's first file) happens
// before anything is applied, so a failure refuses the file whole and the running configuration
// stays.

#include <memory>
#include <string>

#include "daemon/config/daemon_config.hpp"
#include "daemon/core/excitation_exchange.hpp"
#include "daemon/core/loop.hpp"
#include "daemon/outputs/metrics/metrics_publisher.hpp"
#include "daemon/service/recording_control.hpp"
#include "daemon/service/reload.hpp"

namespace scp::daemon {

class Reloader {
 public:
  // Everything referenced must outlive the reloader.
  Reloader(const config::DaemonConfig& started, SafetyCell& safety, ExcitationExchange& excitation,
           const rt::Seqlock<PublishedState>& published, RecordingControl& recording,
           MetricsPublisher& metrics);

  // Re-reads the configuration file and applies what may change; logs what it did.
  void reload();

 private:
  // The parts that can fail, built before anything is applied.
  struct Prepared {
    ReloadPlan plan;
    std::unique_ptr<excitation::Excitation> excitation;
    std::unique_ptr<Recorder> recorder;
  };
  Prepared prepare() const;
  // False when the loop has not taken the previous excitation yet (nothing handed over).
  bool apply_excitation(Prepared& prepared);
  void log_result(const ReloadPlan& plan) const;

  const config::DaemonConfig& started_;
  std::string started_text_;  // the file at the start: restart-only keys are compared with it
  std::string applied_text_;  // the last file applied: reloadable keys are compared with it
  SafetyCell& safety_;
  ExcitationExchange& excitation_;
  const rt::Seqlock<PublishedState>& published_;
  RecordingControl& recording_;
  MetricsPublisher& metrics_;
};

}  // namespace scp::daemon

#pragma once
// The daemon's side of the metrics: every metrics.interval_s the service thread renders STATUS and
// ESTIMATE from the loop's snapshots (the replies a client would get) and writes their Prometheus
// exposition to node_exporter's textfile directory. Never on the loop thread.

#include <chrono>
#include <string>

#include "daemon/analysis/refine/refined_view.hpp"
#include "daemon/config/daemon_config.hpp"
#include "daemon/core/published_state.hpp"
#include "daemon/core/rt/seqlock.hpp"
#include "daemon/outputs/server/settings.hpp"

namespace scp::daemon {

class MetricsPublisher {
 public:
  // `refined` may be null (refinement disabled).
  MetricsPublisher(const config::DaemonConfig& config, server::ServerInfo info,
                   const rt::Seqlock<PublishedState>& published,
                   const rt::Seqlock<refine::RefinedView>* refined);

  // Writes the file when it is due (never when metrics.textfile_directory is empty). A failure
  // is logged once until the next success, which is logged too.
  void poll(std::chrono::steady_clock::time_point now);
  // A reload: the new directory and interval; the next poll writes.
  void apply(const config::MetricsSettings& settings);

 private:
  const config::DaemonConfig& config_;
  config::MetricsSettings settings_;  // config_.metrics, or the last reload's
  server::ServerInfo info_;
  const rt::Seqlock<PublishedState>& published_;
  const rt::Seqlock<refine::RefinedView>* refined_;
  std::chrono::steady_clock::time_point next_;
  std::string last_error_;
};

}  // namespace scp::daemon

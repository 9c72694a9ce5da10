#include "daemon/outputs/metrics/metrics_publisher.hpp"

#include <spdlog/spdlog.h>

#include <nlohmann/json.hpp>

#include "daemon/outputs/log/journal_log.hpp"
#include "daemon/outputs/metrics/exposition.hpp"
#include "daemon/outputs/metrics/textfile.hpp"
#include "daemon/outputs/server/render.hpp"

namespace scp::daemon {

MetricsPublisher::MetricsPublisher(const config::DaemonConfig& config, server::ServerInfo info,
                                   const rt::Seqlock<PublishedState>& published,
                                   const rt::Seqlock<refine::RefinedView>* refined)
    : config_(config),
      settings_(config.metrics),
      info_(std::move(info)),
      published_(published),
      refined_(refined),
      next_(std::chrono::steady_clock::now()) {}

void MetricsPublisher::apply(const config::MetricsSettings& settings) {
  settings_ = settings;
  next_ = std::chrono::steady_clock::now();
  last_error_.clear();
}

void MetricsPublisher::poll(std::chrono::steady_clock::time_point now) {
  if (settings_.textfile_directory.empty() || now < next_) return;
  next_ = now + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                    std::chrono::duration<double>(settings_.interval_s));
  const PublishedState state = published_.load();
  refine::RefinedView view;
  const refine::RefinedView* refined = nullptr;
  if (refined_ != nullptr) {
    view = refined_->load();
    refined = &view;
  }
  const std::string file_name = config_.actuator.name + ".prom";
  try {
    const auto status = nlohmann::json::parse(server::render_status(state, info_, refined));
    const auto estimate =
        nlohmann::json::parse(server::render_estimate(state.estimate, refined, state.uptime_s));
    metrics::write_textfile(settings_.textfile_directory, file_name,
                            metrics::exposition(status, estimate, config_.actuator.name));
    if (!last_error_.empty()) {
      log::notice("metrics: writing {}/{} again", settings_.textfile_directory, file_name);
      last_error_.clear();
    }
  } catch (const std::exception& e) {
    if (e.what() != last_error_) spdlog::warn("metrics: {}", e.what());
    last_error_ = e.what();
  }
}

}  // namespace scp::daemon

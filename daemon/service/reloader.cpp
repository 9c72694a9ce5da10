#include "daemon/service/reloader.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>

#include "daemon/config/config_file.hpp"
#include "daemon/outputs/log/journal_log.hpp"

namespace scp::daemon {

namespace {

std::string joined(const std::vector<std::string>& keys) {
  std::string out;
  for (const auto& key : keys) out += (out.empty() ? "" : ", ") + key;
  return out;
}

bool contains(const std::vector<std::string>& keys, const std::string& key) {
  return std::find(keys.begin(), keys.end(), key) != keys.end();
}

}  // namespace

Reloader::Reloader(const config::DaemonConfig& started, SafetyCell& safety,
                   ExcitationExchange& excitation, const rt::Seqlock<PublishedState>& published,
                   RecordingControl& recording, MetricsPublisher& metrics)
    : started_(started),
      started_text_(started.source.empty() ? "" : config::read_config_file(started.source)),
      applied_text_(started_text_),
      safety_(safety),
      excitation_(excitation),
      published_(published),
      recording_(recording),
      metrics_(metrics) {}

Reloader::Prepared Reloader::prepare() const {
  Prepared p;
  p.plan = plan_reload(started_.source, started_text_, applied_text_);
  // excitation.enabled alone needs no new excitation, only the switch.
  const bool settings_changed =
      std::any_of(p.plan.applied.begin(), p.plan.applied.end(), [](const std::string& k) {
        return in_section(k, "excitation") && k != "excitation.enabled";
      });
  if (settings_changed) {
    p.excitation = std::make_unique<excitation::Excitation>(p.plan.fresh.excitation.settings);
    // Brought to the loop's present time here, so that the loop's first call does not step a
    // PRBS through hours of bits.
    p.excitation->voltage(published_.load().uptime_s);
  }
  if (p.plan.recording) p.recorder = recording_.prepare(p.plan.fresh.recording);
  return p;
}

bool Reloader::apply_excitation(Prepared& p) {
  const std::int8_t enabled = contains(p.plan.applied, "excitation.enabled")
                                  ? (p.plan.fresh.excitation.enabled ? 1 : 0)
                                  : -1;
  if (excitation_.offer(std::move(p.excitation), enabled)) return true;
  spdlog::warn(
      "SIGHUP: the loop has not taken the previous excitation yet; excitation.* not applied, "
      "send SIGHUP again");
  return false;
}

void Reloader::reload() {
  const std::string& source = started_.source;
  if (source.empty()) {
    log::notice("SIGHUP: no configuration file to reload (running on defaults)");
    return;
  }
  Prepared p;
  try {
    p = prepare();
  } catch (const std::exception& e) {
    spdlog::error("SIGHUP: {} refused, the running configuration is kept: {}", source, e.what());
    return;
  }
  const ReloadPlan& plan = p.plan;
  log::set_level(log::parse_level(plan.fresh.log_level).value_or(spdlog::level::info));
  if (plan.safety) safety_.store(plan.fresh.safety);
  // Incomplete: the next SIGHUP compares with the file applied before this one.
  const bool complete = !plan.excitation || apply_excitation(p);
  if (plan.recording) {
    recording_.switch_to(std::move(p.recorder), plan.fresh.recording,
                         published_.load().record_dropped);
  }
  if (plan.metrics) metrics_.apply(plan.fresh.metrics);
  if (complete) applied_text_ = plan.text;
  log_result(plan);
}

void Reloader::log_result(const ReloadPlan& plan) const {
  const std::string& source = started_.source;
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

}  // namespace scp::daemon

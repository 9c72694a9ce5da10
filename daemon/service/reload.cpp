#include "daemon/service/reload.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <map>

#include "daemon/config/config_file.hpp"

namespace scp::daemon {

namespace {

void flatten(const YAML::Node& node, const std::string& prefix,
             std::map<std::string, std::string>& out) {
  if (node.IsMap()) {
    for (const auto& item : node) {
      const std::string key = item.first.as<std::string>();
      flatten(item.second, prefix.empty() ? key : prefix + "." + key, out);
    }
    return;
  }
  YAML::Emitter text;
  text << YAML::Flow << node;
  out[prefix] = text.c_str();
}

std::map<std::string, std::string> flat(const std::string& text) {
  std::map<std::string, std::string> out;
  flatten(YAML::Load(text), "", out);
  return out;
}

}  // namespace

bool in_section(const std::string& key, const std::string& section) {
  return key == section || key.rfind(section + ".", 0) == 0;
}

bool reloadable(const std::string& key) {
  for (const char* section : {"safety", "excitation", "recording", "metrics"})
    if (in_section(key, section)) return true;
  return key == "log_level";
}

std::vector<std::string> changed_keys(const std::string& before, const std::string& after) {
  const auto a = flat(before);
  const auto b = flat(after);
  std::vector<std::string> out;
  for (const auto& [key, value] : a) {
    const auto it = b.find(key);
    if (it == b.end() || it->second != value) out.push_back(key);
  }
  for (const auto& [key, value] : b)
    if (a.find(key) == a.end()) out.push_back(key);
  std::sort(out.begin(), out.end());
  return out;
}

ReloadPlan plan_reload(const std::string& path, const std::string& started_text,
                       const std::string& applied_text) {
  ReloadPlan plan;
  plan.text = config::read_config_file(path);
  plan.fresh = config::load_config_text(plan.text, path);  // every key, range and cross-key check
  for (auto& key : changed_keys(applied_text, plan.text)) {
    if (!reloadable(key)) continue;
    plan.excitation |= in_section(key, "excitation");
    plan.recording |= in_section(key, "recording");
    plan.metrics |= in_section(key, "metrics");
    plan.safety |= in_section(key, "safety");
    plan.applied.push_back(std::move(key));
  }
  for (auto& key : changed_keys(started_text, plan.text)) {
    if (!reloadable(key)) plan.restart.push_back(std::move(key));
  }
  return plan;
}

}  // namespace scp::daemon

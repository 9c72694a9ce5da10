#pragma once
// Reads one driver section ("can:", "modbus:") of a YAML snippet through the Binder, the way the
// daemon's config does, for the drivers' key tests.

#include <yaml-cpp/yaml.h>

#include <string>

#include "daemon/config/binder.hpp"

namespace scp::test {

// `declare` is the section's declare function, e.g. config::declare_can_keys.
template <class Settings, class Declare>
Settings load_section(const std::string& yaml, const char* section, Declare declare) {
  config::Binder root = config::Binder::reading(YAML::Load(yaml), "test.yaml");
  config::Binder keys = root.section(section, "driver section under test");
  Settings out;
  declare(keys, out);
  root.reject_unknown_keys();
  return out;
}

// The ConfigError's message, or `none` when the snippet loads.
template <class Settings, class Declare>
std::string section_error(const std::string& yaml, const char* section, Declare declare,
                          const std::string& none) {
  try {
    load_section<Settings>(yaml, section, declare);
  } catch (const config::ConfigError& e) {
    return e.what();
  }
  return none;
}

}  // namespace scp::test

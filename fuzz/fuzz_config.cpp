// Fuzzes the configuration loader: any text must either load or throw ConfigError (whose message
// names the source); a YAML or std exception leaking out of the loader is a bug, and so is a
// crash, a hang or unbounded memory on hostile YAML (anchors, deep nesting, huge numbers).

#include <cstddef>
#include <cstdint>
#include <string>

#include "daemon/config/binder.hpp"
#include "daemon/config/daemon_config.hpp"
#include "fuzz/fuzz_check.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const scp::config::DaemonConfig cfg = scp::config::load_config_text(text, "fuzz.yaml");
    FUZZ_CHECK(cfg.source == "fuzz.yaml");
    FUZZ_CHECK(cfg.loop.period_s > 0.0);
  } catch (const scp::config::ConfigError& error) {
    const std::string message = error.what();
    FUZZ_CHECK(message.rfind("fuzz.yaml", 0) == 0);  // every message starts with the source name
  }
  return 0;
}

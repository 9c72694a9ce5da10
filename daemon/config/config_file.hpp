#pragma once
// Reading the configuration file itself, before YAML sees it: only a regular file of sane size.
// /dev/zero would be read until bad_alloc, a FIFO would hang the start, a directory would read as
// an empty (all-defaults) configuration.

#include <cstddef>
#include <string>

namespace scp::config {

inline constexpr std::size_t kMaxConfigBytes = 1 << 20;

// The file's text. Throws ConfigError naming the path and the remedy.
std::string read_config_file(const std::string& path);

}  // namespace scp::config

#pragma once
// Names that become file names: an instance's socket and state directory (--instance NAME of
// both programs, scp-estimatord@NAME.service) and an actuator's recordings and metrics file
// (actuator.name). One rule, so that a name one program accepts the other does too.

#include <string>
#include <string_view>

namespace scp::cli {

inline constexpr const char* kRunDirectory = "/run/scp-estimator";
inline constexpr const char* kStateRoot = "/var/lib/scp-estimator";

// 1-64 letters, digits, '.', '_' or '-'.
inline bool is_plain_name(std::string_view name) noexcept {
  constexpr std::string_view kAllowed =
      "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-";
  return !name.empty() && name.size() <= 64 && name.find_first_not_of(kAllowed) == name.npos;
}

// "" when `name` may name an instance (a plain name, not "." or ".."), else why not.
inline std::string instance_name_problem(const std::string& name) {
  if (is_plain_name(name) && name != "." && name != "..") return {};
  return "instance name '" + name +
         "' must be 1-64 letters, digits, '.', '_' or '-' (it becomes a file name)";
}

// /run/scp-estimator/NAME.sock
inline std::string instance_socket(const std::string& name) {
  return std::string(kRunDirectory) + "/" + name + ".sock";
}

}  // namespace scp::cli

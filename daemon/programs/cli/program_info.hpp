#pragma once
// What a program's man page and --help footer say besides its options: one declaration per
// program, next to its CLI11 definitions, so the page, --help and the completion cannot disagree.

#include <string>
#include <utility>
#include <vector>

namespace scp::cli {

// sysexits.h: 64 is what a usage error returns in every program here (CLI11's own 105-109 would
// collide with nothing meaningful and scripts cannot tell them from other failures).
inline constexpr int kExitUsage = 64;
inline constexpr int kExitConfig = 78;
// EX_UNAVAILABLE: the device did not answer within driver.start_timeout_s. The unit does not
// restart on it (RestartPreventExitStatus=): the user asked for a bound, not for a loop.
inline constexpr int kExitUnavailable = 69;

struct ProgramInfo {
  std::string name;                      // "scp-estimatorctl"
  int section = 1;                       // man section: 1 user command, 8 daemon
  std::string summary;                   // NAME line: "query and command scp-estimatord"
  std::vector<std::string> synopsis;     // one usage per line, after the name: "[OPTIONS] COMMAND"
  std::vector<std::string> description;  // paragraphs
  std::vector<std::pair<std::string, std::string>> exit_codes;  // {"0", "success"}
  std::vector<std::pair<std::string, std::string>> environment;
  std::vector<std::pair<std::string, std::string>> files;
  std::vector<std::pair<std::string, std::string>> examples;  // {command, what it does}
  std::vector<std::string> see_also;                          // "scp-estimatord(8)"
  // Words completed after a subcommand besides its options (e.g. "excitation" -> "on off").
  std::vector<std::pair<std::string, std::string>> completion_words;
};

}  // namespace scp::cli

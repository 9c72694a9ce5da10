#pragma once
// The command-line conventions of every scp-estimator program, applied to its CLI11 App:
// --version, a --help footer with the exit codes and the man page, options accepted after a
// subcommand, usage errors exiting 64 (EX_USAGE), an unknown subcommand named with the closest
// one. Hidden --man-page and --bash-completion print the page and the completion generated from
// the same App (CMake installs their output).

#include <CLI/CLI.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "daemon/programs/cli/program_info.hpp"

namespace scp::cli {

// The release, from CMake's project(VERSION).
const char* version() noexcept;

// Call after creating the App and before adding options or subcommands (subcommands inherit
// fallthrough, so `prog sub --global-option` works).
void prepare(CLI::App& app, const ProgramInfo& info);

// Parses argv. Returns std::nullopt when the program should go on, else the exit code: 0 after
// --help/--version/--man-page/--bash-completion, kExitUsage after a usage error (printed to stderr
// with a hint). Call after every option and subcommand has been added.
std::optional<int> parse(CLI::App& app, int argc, const char* const* argv, const ProgramInfo& info);

// The candidate closest to `word` by edit distance, or "" when none is plausibly meant.
std::string closest(std::string_view word, const std::vector<std::string>& candidates);

// roff man page and bash completion script of `app`.
std::string man_page(const CLI::App& app, const ProgramInfo& info);
std::string bash_completion(const CLI::App& app, const ProgramInfo& info);

}  // namespace scp::cli

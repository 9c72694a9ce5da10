#include "daemon/programs/cli/conventions.hpp"

#include <algorithm>
#include <cstdio>
#include <iostream>

#ifndef SCP_VERSION
#error "SCP_VERSION comes from CMake's project(VERSION)"
#endif

namespace scp::cli {

namespace {

bool is_named_subcommand(const CLI::App* sub) {
  return !sub->get_name().empty();
}

std::vector<std::string> subcommand_names(const CLI::App& app) {
  std::vector<std::string> names;
  for (const CLI::App* sub : app.get_subcommands(is_named_subcommand)) {
    names.push_back(sub->get_name());
  }
  return names;
}

std::vector<std::string> option_names(const CLI::App& app) {
  std::vector<std::string> names;
  for (const CLI::Option* opt : app.get_options()) {
    for (const auto& l : opt->get_lnames()) names.push_back(std::string("--").append(l));
  }
  for (const CLI::App* sub : app.get_subcommands(is_named_subcommand)) {
    for (auto& name : option_names(*sub)) names.push_back(std::move(name));
  }
  return names;
}

std::string footer(const ProgramInfo& info) {
  std::string out = "Exit status:\n";
  for (const auto& [code, meaning] : info.exit_codes) {
    out += "  " + code + std::string(code.size() < 4 ? 4 - code.size() : 0, ' ') + meaning + '\n';
  }
  out += "\nSee " + info.name + "(" + std::to_string(info.section) + ")";
  for (std::size_t i = 0; i < info.see_also.size(); ++i) {
    out += i == 0 ? "; also " : ", ";
    out += info.see_also[i];
  }
  out += ".\n";
  return out;
}

// Index of the first argument that is neither an option nor the value of one, or argc.
int first_word(const CLI::App& app, int argc, const char* const* argv) {
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    if (arg == "--") return i + 1;
    if (arg.size() > 1 && arg[0] == '-') {
      if (arg.find('=') != std::string_view::npos) continue;
      const CLI::Option* opt = app.get_option_no_throw(std::string(arg));
      if (opt != nullptr && opt->get_items_expected_min() > 0) ++i;
      continue;
    }
    return i;
  }
  return argc;
}

bool asks_for_help_or_version(int argc, const char* const* argv) {
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    if (arg == "-h" || arg == "--help" || arg == "--help-all" || arg == "--version") return true;
  }
  return false;
}

int usage_error(const ProgramInfo& info, const std::string& message) {
  std::fprintf(stderr, "%s: %s\nRun '%s --help' for usage.\n", info.name.c_str(), message.c_str(),
               info.name.c_str());
  return kExitUsage;
}

std::string join(const std::vector<std::string>& words) {
  std::string out;
  for (const auto& w : words) {
    if (!out.empty()) out += ", ";
    out += w;
  }
  return out;
}

}  // namespace

const char* version() noexcept {
  return SCP_VERSION;
}

void prepare(CLI::App& app, const ProgramInfo& info) {
  app.name(info.name);
  app.set_version_flag("--version", info.name + " " + version());
  app.fallthrough();
  app.footer(footer(info));
}

std::string closest(std::string_view word, const std::vector<std::string>& candidates) {
  std::string best;
  std::size_t best_distance = std::string::npos;
  for (const auto& candidate : candidates) {
    // Levenshtein distance, two rows.
    std::vector<std::size_t> previous(candidate.size() + 1), current(candidate.size() + 1);
    for (std::size_t j = 0; j <= candidate.size(); ++j) previous[j] = j;
    for (std::size_t i = 1; i <= word.size(); ++i) {
      current[0] = i;
      for (std::size_t j = 1; j <= candidate.size(); ++j) {
        const std::size_t substitute = previous[j - 1] + (word[i - 1] == candidate[j - 1] ? 0 : 1);
        current[j] = std::min({previous[j] + 1, current[j - 1] + 1, substitute});
      }
      std::swap(previous, current);
    }
    if (previous[candidate.size()] < best_distance) {
      best_distance = previous[candidate.size()];
      best = candidate;
    }
  }
  // "stauts" is 2 edits from "status"; a word sharing nothing with the candidate is not a typo.
  const std::size_t allowed = std::max<std::size_t>(2, word.size() / 3);
  return best_distance <= allowed ? best : std::string();
}

std::optional<int> parse(CLI::App& app, int argc, const char* const* argv,
                         const ProgramInfo& info) {
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    if (arg == "--man-page") {
      std::cout << man_page(app, info);
      return 0;
    }
    if (arg == "--bash-completion") {
      std::cout << bash_completion(app, info);
      return 0;
    }
  }
  const std::vector<std::string> commands = subcommand_names(app);
  const bool help = asks_for_help_or_version(argc, argv);
  if (!commands.empty() && !help) {
    const int w = first_word(app, argc, argv);
    if (w >= argc) return usage_error(info, "a command is required: " + join(commands));
    const std::string word = argv[w];
    if (std::find(commands.begin(), commands.end(), word) == commands.end()) {
      const std::string guess = closest(word, commands);
      return usage_error(info, "unknown command '" + word + "'" +
                                   (guess.empty() ? "" : "; did you mean '" + guess + "'?") +
                                   " (commands: " + join(commands) + ")");
    }
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ExtrasError& e) {
    // Name the closest option for the first unexpected argument.
    std::string message = e.what();
    for (int i = 1; i < argc; ++i) {
      const std::string arg = argv[i];
      if (arg.size() > 2 && arg.compare(0, 2, "--") == 0 &&
          message.find(arg) != std::string::npos) {
        const std::string guess = closest(arg.substr(0, arg.find('=')), option_names(app));
        if (!guess.empty()) message += "; did you mean '" + guess + "'?";
        break;
      }
    }
    return usage_error(info, message);
  } catch (const CLI::ParseError& e) {
    return usage_error(info, e.what());
  }
  return std::nullopt;
}

}  // namespace scp::cli

// A man(7) page from a CLI11 App and its ProgramInfo: the options and commands are the ones the
// program parses, so the page cannot list an option that does not exist or miss one that does.

#include "daemon/programs/cli/conventions.hpp"
#include "daemon/programs/cli/roff.hpp"

namespace scp::cli {

namespace {

bool visible(const CLI::Option* opt) {
  return !opt->get_group().empty();
}

// "\fB\-c\fR, \fB\-\-config\fR \fIFILE\fR"
std::string option_heading(const CLI::Option* opt) {
  std::string out;
  if (!opt->nonpositional()) return "\\fI" + roff_escape(opt->get_name(true)) + "\\fR";
  // (Appended piecewise: GCC 12 reports a false -Wrestrict on "a" + std::string&&.)
  auto add = [&out](const std::string& dashes, const std::string& name) {
    if (!out.empty()) out += ", ";
    out += "\\fB";
    out += dashes;
    out += roff_escape(name);
    out += "\\fR";
  };
  for (const auto& s : opt->get_snames()) add("\\-", s);
  for (const auto& l : opt->get_lnames()) add("\\-\\-", l);
  if (opt->get_items_expected_min() > 0) {
    out += " \\fI" + roff_escape(opt->get_type_name()) + "\\fR";
  }
  return out;
}

void options_list(std::string& out, const CLI::App& app) {
  for (const CLI::Option* opt : app.get_options(visible)) {
    out += ".TP\n" + option_heading(opt) + "\n" + roff_escape(opt->get_description());
    if (!opt->get_default_str().empty())
      out += " (default: " + roff_escape(opt->get_default_str()) + ")";
    out += "\n";
  }
}

void pairs(std::string& out, const char* heading,
           const std::vector<std::pair<std::string, std::string>>& items, bool bold) {
  if (items.empty()) return;
  out += std::string(".SH ") + heading + "\n";
  for (const auto& [term, text] : items) {
    out += ".TP\n" + std::string(bold ? "\\fB" : "\\fI") + roff_escape(term) + "\\fR\n" +
           roff_escape(text) + "\n";
  }
}

}  // namespace

std::string man_page(const CLI::App& app, const ProgramInfo& info) {
  std::string out = roff_header(info.name, info.section, version(),
                                info.section == 8 ? "System Administration" : "User Commands");
  out += ".SH NAME\n" + roff_escape(info.name) + " \\- " + roff_escape(info.summary) + "\n";
  out += ".SH SYNOPSIS\n";
  for (std::size_t i = 0; i < info.synopsis.size(); ++i) {
    out += (i ? ".br\n" : "") + (".B " + roff_escape(info.name) + "\n") +
           roff_escape(info.synopsis[i]) + "\n";
  }
  out += ".SH DESCRIPTION\n";
  for (std::size_t i = 0; i < info.description.size(); ++i) {
    out += (i ? ".PP\n" : "") + roff_escape(info.description[i]) + "\n";
  }
  out += ".SH OPTIONS\n";
  options_list(out, app);
  const auto subs = app.get_subcommands([](const CLI::App* s) { return !s->get_name().empty(); });
  if (!subs.empty()) {
    out += ".SH COMMANDS\nOptions may be given before or after the command.\n";
    for (const CLI::App* sub : subs) {
      std::string heading = "\\fB" + roff_escape(sub->get_name()) + "\\fR";
      for (const CLI::Option* opt : sub->get_options(visible)) {
        if (!opt->nonpositional()) heading += " " + option_heading(opt);
      }
      out += ".TP\n" + heading + "\n" + roff_escape(sub->get_description()) + "\n";
      bool any = false;
      for (const CLI::Option* opt : sub->get_options(visible)) {
        if (opt->nonpositional() && opt != sub->get_help_ptr()) any = true;
      }
      if (!any) continue;
      out += ".RS\n";
      for (const CLI::Option* opt : sub->get_options(visible)) {
        if (!opt->nonpositional() || opt == sub->get_help_ptr()) continue;
        out += ".TP\n" + option_heading(opt) + "\n" + roff_escape(opt->get_description()) + "\n";
      }
      out += ".RE\n";
    }
  }
  pairs(out, "EXIT STATUS", info.exit_codes, true);
  pairs(out, "ENVIRONMENT", info.environment, true);
  pairs(out, "FILES", info.files, false);
  if (!info.examples.empty()) {
    out += ".SH EXAMPLES\n";
    for (const auto& [command, what] : info.examples) {
      out += ".PP\n" + roff_escape(what) + "\n.PP\n.RS 4\n.nf\n" + roff_escape(command) +
             "\n.fi\n.RE\n";
    }
  }
  if (!info.see_also.empty()) {
    out += ".SH SEE ALSO\n";
    for (std::size_t i = 0; i < info.see_also.size(); ++i) {
      const std::string& page = info.see_also[i];
      const auto paren = page.find('(');
      out += ".BR " + roff_escape(page.substr(0, paren)) + " " + page.substr(paren) +
             (i + 1 < info.see_also.size() ? "," : "") + "\n";
    }
  }
  return out;
}

}  // namespace scp::cli

#pragma once
// Escaping text for man(7) roff: a backslash is \e, a hyphen in an option name is \-, and a line
// starting with '.' or '\'' would be read as a request.

#include <string>
#include <string_view>

namespace scp::cli {

inline std::string roff_escape(std::string_view text) {
  std::string out;
  bool line_start = true;
  for (const char c : text) {
    if (line_start && (c == '.' || c == '\'')) out += "\\&";
    if (c == '\\') {
      out += "\\e";
    } else if (c == '-') {
      out += "\\-";
    } else {
      out += c;
    }
    line_start = c == '\n';
  }
  return out;
}

// .TH line; the date is left out so that the pages are reproducible.
inline std::string roff_header(std::string_view name, int section, std::string_view version,
                               std::string_view manual) {
  std::string upper;
  for (const char c : name) upper += static_cast<char>(c >= 'a' && c <= 'z' ? c - 'a' + 'A' : c);
  return ".TH " + roff_escape(upper) + " " + std::to_string(section) + " \"\" \"scp-estimator " +
         std::string(version) + "\" \"" + std::string(manual) +
         "\"\n"
         // Ragged right, no hyphenation: long key names and values cannot be justified at 80
         // columns (groff warns "cannot adjust line", which lintian reports).
         ".ad l\n.nh\n";
}

}  // namespace scp::cli

// scp-estimator.yaml(5): the configuration reference as a man page, from the same declarations
// that read the file and generate docs/configuration.md (declare_daemon_keys).

#include "daemon/config/reference_man.hpp"

#include <sstream>

#include "daemon/config/binder.hpp"
#include "daemon/config/daemon_config.hpp"
#include "daemon/programs/cli/roff.hpp"

namespace scp::config {

std::string config_reference_man(std::string_view version) {
  using cli::roff_escape;
  DaemonConfig defaults;
  Binder doc = Binder::documenting();
  declare_daemon_keys(doc, defaults);
  std::ostringstream out;
  out << cli::roff_header("scp-estimator.yaml", 5, version, "File Formats")
      << ".SH NAME\nscp\\-estimator.yaml \\- configuration of scp\\-estimatord\n"
      << ".SH SYNOPSIS\n/etc/scp\\-estimator/scp\\-estimator.yaml\n"
      << ".SH DESCRIPTION\n"
      << roff_escape(
             "scp-estimatord(8) reads one YAML file: a mapping of sections, each a mapping of "
             "keys. Every key is optional; its default applies when it is missing. A key nobody "
             "declared, a key given twice, a value of the wrong type or outside its range is an "
             "error that names the file, the line, the key and what is allowed; the daemon then "
             "exits with status 78 and systemd does not restart it.")
      << "\n.PP\n"
      << roff_escape(
             "Check a file before restarting the service with scp-estimatord --check-config FILE. "
             "Besides the keys, it reports what would stop the daemon at start-up (a missing "
             "socket group, replay file or state directory) and warns about values that are "
             "valid but suspicious (a temperature limit that looks like kelvin, an excitation "
             "above the voltage limit).")
      << "\n.PP\n"
      << roff_escape(
             "Lists are written in brackets, e.g. theta0: [0, 0, 1813, 0, 0, 0]; lists of "
             "mappings (excitation.sines) one \"- key: value\" item per element. The keys of "
             "one element are shown as name[].key below.")
      << "\n.SH KEYS\n";
  for (const auto& key : doc.docs()) {
    if (key.type == "section") {
      const bool top = key.path.find('.') == std::string::npos;
      out << (top ? ".SS " : ".TP\n\\fB") << roff_escape(key.path) << (top ? "" : "\\fR") << "\n"
          << roff_escape(key.doc) << (top ? ".\n" : " (section).\n");
      continue;
    }
    // "a|b|c" as "a | b | c": one unbreakable word could not fit 80 columns.
    std::string type;
    for (const char c : key.type) type += c == '|' ? std::string(" | ") : std::string(1, c);
    out << ".TP\n\\fB" << roff_escape(key.path) << "\\fR (" << roff_escape(type);
    if (!key.deflt.empty()) out << ", default " << roff_escape(key.deflt);
    if (!key.range.empty() && key.type.rfind("one of", 0) != 0)
      out << ", allowed " << roff_escape(key.range);
    out << ")\n" << roff_escape(key.doc) << "\n";
  }
  out << ".SH FILES\n.TP\n\\fI/etc/scp\\-estimator/scp\\-estimator.yaml\\fR\n"
      << "the configuration the service reads (a conffile: upgrades keep your edits)\n"
      << ".TP\n\\fI/usr/share/doc/scp\\-estimator/examples/\\fR\n"
      << "example configurations: sim.yaml (the default), paper.yaml (the paper's experiment), "
         "modbus\\-tcp.yaml, modbus\\-rtu.yaml, can.yaml\n"
      << ".SH SEE ALSO\n.BR scp\\-estimatord (8),\n.BR scp\\-estimatorctl (1),\n"
      << ".BR scp\\-simdaq (1)\n";
  return out.str();
}

}  // namespace scp::config

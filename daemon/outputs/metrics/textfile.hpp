#pragma once
// Writes the metrics file for node_exporter's textfile collector atomically: the text goes to a
// temporary file in the same directory, which is then renamed over the target, so that the
// collector never reads half a file (node_exporter's documentation asks for exactly this).

#include <string>

namespace scp::daemon::metrics {

// Throws std::runtime_error naming the path, the errno text and the remedy.
void write_textfile(const std::string& directory, const std::string& file_name,
                    const std::string& text);

}  // namespace scp::daemon::metrics

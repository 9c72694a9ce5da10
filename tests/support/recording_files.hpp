#pragma once
// Reading a recording directory in tests: its files by suffix, in name order, and a CSV row's
// fields (the recorder writes plain comma-separated numbers and words, no quoting).

#include <algorithm>
#include <filesystem>
#include <sstream>
#include <string>
#include <system_error>
#include <vector>

namespace scp::test {

// Files in `directory` whose name ends with `tail` (".csv", ".csv.gz", ".tmp"), sorted; none if
// the directory does not exist.
inline std::vector<std::string> files_ending(const std::string& directory,
                                             const std::string& tail) {
  std::vector<std::string> out;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(directory, ec)) {
    const std::string path = entry.path().string();
    if (path.size() >= tail.size() &&
        path.compare(path.size() - tail.size(), tail.size(), tail) == 0)
      out.push_back(path);
  }
  std::sort(out.begin(), out.end());
  return out;
}

inline std::vector<std::string> split_csv(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream in(line);
  for (std::string field; std::getline(in, field, ',');) out.push_back(field);
  return out;
}

}  // namespace scp::test

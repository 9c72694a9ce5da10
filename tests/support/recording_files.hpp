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

// "a,b," has three fields, the last empty (a recording's V_since where the voltage held the whole
// interval).
inline std::vector<std::string> split_csv(const std::string& line) {
  std::vector<std::string> out;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = line.find(',', start);
    out.push_back(
        line.substr(start, comma == std::string::npos ? std::string::npos : comma - start));
    if (comma == std::string::npos) return out;
    start = comma + 1;
  }
}

}  // namespace scp::test

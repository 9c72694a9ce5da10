#include "drivers/replay/csv_trace.hpp"

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string_view>

namespace scp::drivers::replay {

namespace {

constexpr std::array<std::string_view, 5> kColumns = {"t", "x", "xdot", "T", "V"};
enum Column : std::size_t { kT, kX, kXdot, kTemp, kV };

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

std::string_view trim(std::string_view s) {
  const auto* ws = " \t\r\n";
  const auto b = s.find_first_not_of(ws);
  if (b == std::string_view::npos) return {};
  return s.substr(b, s.find_last_not_of(ws) - b + 1);
}

// Splits on ',' into `out` (reused between lines).
void split(std::string_view line, std::vector<std::string_view>& out) {
  out.clear();
  std::size_t start = 0;
  while (true) {
    const auto comma = line.find(',', start);
    out.push_back(
        trim(line.substr(start, comma == std::string_view::npos ? line.npos : comma - start)));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
}

[[noreturn]] void fail(const std::string& path, std::size_t line, const std::string& message) {
  throw TraceError(path + ":" + std::to_string(line) + ": " + message);
}

std::string column_ref(std::string_view name, std::size_t field) {
  return "column '" + std::string(name) + "' (field " + std::to_string(field + 1) + ")";
}

// std::from_chars: no locale, so "1.5" reads the same everywhere; accepts nan and inf.
bool parse_double(std::string_view text, double& out) {
  if (!text.empty() && text.front() == '+') text.remove_prefix(1);
  if (text.empty()) return false;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), out);
  return ec == std::errc() && ptr == text.data() + text.size();
}

bool is_skipped(std::string_view line) {
  return line.empty() || line.front() == '#';
}

}  // namespace

Trace load_trace(const std::string& path) {
  std::ifstream in(path);
  if (!in) {
    throw TraceError(path + ": cannot open trace file (" + std::strerror(errno) +
                     "); check the path and read permission");
  }
  return parse_trace(in, path);
}

Trace parse_trace(std::istream& in, const std::string& path) {
  std::string raw;
  std::size_t line_no = 0;
  std::vector<std::string_view> fields;

  // Header: the first line that is neither blank nor a comment.
  std::size_t header_line = 0;
  std::vector<std::string> header;
  while (std::getline(in, raw)) {
    ++line_no;
    if (line_no == 1 && raw.rfind("\xEF\xBB\xBF", 0) == 0) raw.erase(0, 3);  // UTF-8 BOM
    const std::string_view line = trim(raw);
    if (is_skipped(line)) continue;
    split(line, fields);
    header.assign(fields.begin(), fields.end());
    header_line = line_no;
    break;
  }
  if (header_line == 0) {
    throw TraceError(path +
                     ": empty file (no header line); the first line must name the columns, "
                     "e.g. t,x,xdot,T,V");
  }

  std::array<std::size_t, kColumns.size()> index{};
  for (std::size_t c = 0; c < kColumns.size(); ++c) {
    const auto it = std::find(header.begin(), header.end(), kColumns[c]);
    if (it == header.end()) {
      fail(path, header_line,
           "missing column '" + std::string(kColumns[c]) +
               "' in the header; it must name t, x, xdot, T and V (any order, case-sensitive; "
               "other columns are ignored)");
    }
    if (std::find(it + 1, header.end(), kColumns[c]) != header.end()) {
      fail(path, header_line,
           "column '" + std::string(kColumns[c]) + "' appears twice in the header; keep one");
    }
    index[c] = static_cast<std::size_t>(it - header.begin());
  }

  Trace trace;
  std::vector<std::size_t> row_lines;
  while (std::getline(in, raw)) {
    ++line_no;
    const std::string_view line = trim(raw);
    if (is_skipped(line)) continue;
    split(line, fields);
    if (fields.size() != header.size()) {
      fail(path, line_no,
           std::to_string(fields.size()) + " fields, but the header (line " +
               std::to_string(header_line) + ") has " + std::to_string(header.size()) +
               "; every row needs one value per header column");
    }
    std::array<double, kColumns.size()> v{};
    for (std::size_t c = 0; c < kColumns.size(); ++c) {
      const std::string_view text = fields[index[c]];
      if (c == kXdot && (text.empty() || text == "nan" || text == "NaN" || text == "NAN")) {
        v[c] = kNotMeasured;  // velocity not measured on this device
        continue;
      }
      if (text.empty()) {
        fail(path, line_no,
             column_ref(kColumns[c], index[c]) +
                 " is empty; only xdot may be left blank (not measured)");
      }
      if (!parse_double(text, v[c])) {
        fail(path, line_no,
             column_ref(kColumns[c], index[c]) + ": cannot parse '" + std::string(text) +
                 "' as a number; write plain numbers with '.' as decimal point (e.g. 1.5e-3)");
      }
    }
    if (!std::isfinite(v[kT])) {
      fail(path, line_no,
           column_ref("t", index[kT]) + ": time '" + std::string(fields[index[kT]]) +
               "' is not finite; every row needs a finite time in seconds");
    }
    if (!trace.rows.empty() && !(v[kT] > trace.rows.back().t)) {
      fail(path, line_no,
           column_ref("t", index[kT]) + ": time " + num(v[kT]) +
               " is not after the previous row's " + num(trace.rows.back().t) + " (line " +
               std::to_string(row_lines.back()) +
               "); rows must be in strictly increasing time order, without duplicates");
    }
    Sample s;
    s.t = v[kT];
    s.x = v[kX];
    s.xdot = v[kXdot];
    s.temperature = v[kTemp];
    s.voltage = v[kV];
    trace.rows.push_back(s);
    row_lines.push_back(line_no);
  }

  if (trace.rows.size() < 2) {
    throw TraceError(path + ": only " + std::to_string(trace.rows.size()) +
                     " data row(s) after the header (line " + std::to_string(header_line) +
                     "); at least 2 are needed to know the sample period");
  }

  std::vector<double> steps(trace.rows.size() - 1);
  for (std::size_t i = 1; i < trace.rows.size(); ++i) {
    steps[i - 1] = trace.rows[i].t - trace.rows[i - 1].t;
  }
  std::vector<double> sorted = steps;
  const auto mid = sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2);
  std::nth_element(sorted.begin(), mid, sorted.end());
  const double median = *mid;
  for (std::size_t i = 0; i < steps.size(); ++i) {
    if (std::abs(steps[i] - median) > kPeriodTolerance * median) {
      fail(path, row_lines[i + 1],
           column_ref("t", index[kT]) + ": step " + num(steps[i]) + " s from line " +
               std::to_string(row_lines[i]) + " differs from the median step " + num(median) +
               " s by more than 1e-6 relative; the trace must be sampled uniformly (rows "
               "missing or duplicated? t written with too few digits?)");
    }
  }
  trace.period = median;
  return trace;
}

}  // namespace scp::drivers::replay

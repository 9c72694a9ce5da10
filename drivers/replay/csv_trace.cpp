#include "drivers/replay/csv_trace.hpp"

#include <zlib.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string_view>

#include "common/checks.hpp"

namespace scp::drivers::replay {

namespace {

constexpr std::array<std::string_view, 5> kColumns = {"t", "x", "xdot", "T", "V"};
enum Column : std::size_t { kT, kX, kXdot, kTemp, kV };
// Optional: when the row's voltage took effect (drivers/sample.hpp, Sample::voltage_since). The
// daemon records it on a link that stamps its writes; blank (or no such column) means the voltage
// was applied over the whole interval.
constexpr std::string_view kVoltageSinceColumn = "V_since";
// Optional: the heater's current in A (Sample::current); blank or nan: not measured.
constexpr std::string_view kCurrentColumn = "I";

// Values quoted from the file read back as the same doubles.
using checks::exact_num;

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

// The period (median step: robust to the gaps of missed periods), the gaps and the longest step.
void finish(Trace& trace) {
  std::vector<double> steps(trace.rows.size() - 1);
  for (std::size_t i = 1; i < trace.rows.size(); ++i) {
    steps[i - 1] = trace.rows[i].t - trace.rows[i - 1].t;
  }
  std::vector<double> sorted = steps;
  const auto mid = sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2);
  std::nth_element(sorted.begin(), mid, sorted.end());
  trace.period = *mid;
  trace.gaps = 0;
  trace.max_step = 0.0;
  for (const double step : steps) {
    if (step > 1.5 * trace.period) ++trace.gaps;
    trace.max_step = std::max(trace.max_step, step);
  }
}

bool ends_with(const std::string& s, std::string_view tail) {
  return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

// The .csv and .csv.gz files of a directory in name order (the daemon's names sort in time
// order). A.csv and A.csv.gz are one recording (both exist while A is being compressed, or after
// a crash in between): the plain file is taken.
std::vector<std::string> csv_files_in(const std::string& directory) {
  std::vector<std::string> out;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(directory, ec)) {
    const std::string path = entry.path().string();
    if (!entry.is_regular_file()) continue;
    if (ends_with(path, ".csv")) out.push_back(path);
    if (ends_with(path, ".csv.gz") && !std::filesystem::exists(path.substr(0, path.size() - 3), ec))
      out.push_back(path);
  }
  if (ec) {
    throw TraceError(directory + ": cannot list the directory (" + ec.message() +
                     "); check the path and permissions");
  }
  if (out.empty()) throw TraceError(directory + ": no .csv or .csv.gz files in this directory");
  // By the plain name, so that A.csv.gz sorts as A.csv would.
  auto stem = [](const std::string& p) {
    return ends_with(p, ".gz") ? std::string_view(p).substr(0, p.size() - 3) : std::string_view(p);
  };
  std::sort(out.begin(), out.end(),
            [&](const std::string& a, const std::string& b) { return stem(a) < stem(b); });
  return out;
}

// The whole text of a gzip file. zlib checks the CRC-32 and length at the end, so a corrupt or
// truncated file fails here, before a single row is used.
std::string read_gzip(const std::string& path) {
  gzFile file = gzopen(path.c_str(), "rb");
  if (file == nullptr) {
    throw TraceError(path + ": cannot open trace file (" + std::strerror(errno) +
                     "); check the path and read permission");
  }
  gzbuffer(file, 256 * 1024);
  std::string text;
  std::vector<char> chunk(256 * 1024);
  std::string error;
  for (;;) {
    const int n = gzread(file, chunk.data(), static_cast<unsigned>(chunk.size()));
    if (n > 0) text.append(chunk.data(), static_cast<std::size_t>(n));
    int code = Z_OK;
    const char* message = gzerror(file, &code);
    if (code != Z_OK && code != Z_STREAM_END) {
      error = message != nullptr ? message : "unknown zlib error";
      break;
    }
    if (n <= 0) break;
  }
  const bool direct = gzdirect(file) != 0;
  gzclose(file);
  if (direct) {
    throw TraceError(path +
                     ": not gzip data, though the name ends in .gz; rename it to .csv if it is a "
                     "plain CSV");
  }
  if (!error.empty()) {
    const auto lines = static_cast<std::size_t>(std::count(text.begin(), text.end(), '\n'));
    throw TraceError(path + ": corrupt or truncated gzip data after line " + std::to_string(lines) +
                     " (zlib: " + error + "); no row of this file was used. `zcat " + path +
                     " > part.csv` keeps the readable rows, which replay on their own");
  }
  return text;
}

}  // namespace

namespace {

// The rows of one file, without the minimum count: one file of a rotated recording may hold a
// single row (the daemon stopped just after a rotation).
Trace parse_rows(std::istream& in, const std::string& path, std::size_t& header_line_out);

Trace load_rows(const std::string& path, std::size_t& header_line) {
  if (ends_with(path, ".gz")) {
    std::istringstream text(read_gzip(path));
    return parse_rows(text, path, header_line);
  }
  std::ifstream in(path);
  if (!in) {
    throw TraceError(path + ": cannot open trace file (" + std::strerror(errno) +
                     "); check the path and read permission");
  }
  return parse_rows(in, path, header_line);
}

void require_two_rows(const Trace& trace, const std::string& path, std::size_t header_line) {
  if (trace.rows.size() < 2) {
    throw TraceError(path + ": only " + std::to_string(trace.rows.size()) +
                     " data row(s) after the header (line " + std::to_string(header_line) +
                     "); at least 2 are needed to know the sample period");
  }
}

}  // namespace

Trace parse_trace(std::istream& in, const std::string& path) {
  std::size_t header_line = 0;
  Trace trace = parse_rows(in, path, header_line);
  require_two_rows(trace, path, header_line);
  finish(trace);
  return trace;
}

namespace {

// V_since of one row: blank is −∞ (the whole interval); otherwise a finite time not after the
// row's own t (a voltage cannot take effect after the sample that reports it).
double parse_voltage_since(std::string_view text, double t, const std::string& path,
                           std::size_t line_no, std::size_t field) {
  if (text.empty()) return -std::numeric_limits<double>::infinity();
  double since = 0.0;
  if (!parse_double(text, since) || !std::isfinite(since)) {
    fail(path, line_no,
         column_ref(kVoltageSinceColumn, field) + ": cannot use '" + std::string(text) +
             "'; write the time (s, same clock as t) the row's V took effect, or leave it blank "
             "when V was applied over the whole interval");
  }
  if (since > t) {
    fail(path, line_no,
         column_ref(kVoltageSinceColumn, field) + ": " + exact_num(since) +
             " is after the row's t " + exact_num(t) +
             "; V_since is when the voltage read at t took effect, so it cannot be later");
  }
  return since;
}

// I of one row: blank or nan is "not measured"; ±inf is loaded as-is, like x, T and V, for the
// loop's safety check to see.
double parse_current(std::string_view text, const std::string& path, std::size_t line_no,
                     std::size_t field) {
  if (text.empty() || text == "nan" || text == "NaN" || text == "NAN") return kNotMeasured;
  double current = 0.0;
  if (!parse_double(text, current)) {
    fail(path, line_no,
         column_ref(kCurrentColumn, field) + ": cannot parse '" + std::string(text) +
             "' as a current; write the heater's current in A with '.' as decimal point, or "
             "leave it blank when it was not measured");
  }
  return current;
}

// The file's lines that hold data (not blank, not a comment), numbered for the messages.
class LineReader {
 public:
  explicit LineReader(std::istream& in) : in_(in) {}
  bool next(std::string_view& line) {
    while (std::getline(in_, raw_)) {
      ++line_no_;
      if (line_no_ == 1 && raw_.rfind("\xEF\xBB\xBF", 0) == 0) raw_.erase(0, 3);  // UTF-8 BOM
      line = trim(raw_);
      if (!is_skipped(line)) return true;
    }
    return false;
  }
  std::size_t line_no() const noexcept { return line_no_; }

 private:
  std::istream& in_;
  std::string raw_;
  std::size_t line_no_ = 0;
};

// Where the columns are: t, x, xdot, T and V in any order, V_since when present.
struct Header {
  std::size_t line = 0;
  std::size_t fields = 0;
  std::array<std::size_t, kColumns.size()> index{};
  bool has_since = false;
  std::size_t since_index = 0;
  bool has_current = false;
  std::size_t current_index = 0;
};

// The first line that is neither blank nor a comment names the columns.
Header read_header(LineReader& reader, const std::string& path) {
  std::string_view line;
  if (!reader.next(line)) {
    throw TraceError(path +
                     ": empty file (no header line); the first line must name the columns, "
                     "e.g. t,x,xdot,T,V");
  }
  std::vector<std::string_view> fields;
  split(line, fields);
  const std::vector<std::string> header(fields.begin(), fields.end());
  Header h;
  h.line = reader.line_no();
  h.fields = header.size();
  const auto unique = [&](std::vector<std::string>::const_iterator it, std::string_view name) {
    if (std::find(it + 1, header.end(), name) != header.end()) {
      fail(path, h.line,
           "column '" + std::string(name) + "' appears twice in the header; keep one");
    }
  };
  for (std::size_t c = 0; c < kColumns.size(); ++c) {
    const auto it = std::find(header.begin(), header.end(), kColumns[c]);
    if (it == header.end()) {
      fail(path, h.line,
           "missing column '" + std::string(kColumns[c]) +
               "' in the header; it must name t, x, xdot, T and V (any order, case-sensitive; "
               "other columns are ignored)");
    }
    unique(it, kColumns[c]);
    h.index[c] = static_cast<std::size_t>(it - header.begin());
  }
  const auto since = std::find(header.begin(), header.end(), kVoltageSinceColumn);
  h.has_since = since != header.end();
  if (h.has_since) unique(since, kVoltageSinceColumn);
  h.since_index = static_cast<std::size_t>(since - header.begin());
  const auto current = std::find(header.begin(), header.end(), kCurrentColumn);
  h.has_current = current != header.end();
  if (h.has_current) unique(current, kCurrentColumn);
  h.current_index = static_cast<std::size_t>(current - header.begin());
  return h;
}

// The five required values of a row; only xdot may be blank (not measured).
std::array<double, kColumns.size()> parse_values(const std::vector<std::string_view>& fields,
                                                 const Header& h, const std::string& path,
                                                 std::size_t line_no) {
  std::array<double, kColumns.size()> v{};
  for (std::size_t c = 0; c < kColumns.size(); ++c) {
    const std::string_view text = fields[h.index[c]];
    if (c == kXdot && (text.empty() || text == "nan" || text == "NaN" || text == "NAN")) {
      v[c] = kNotMeasured;  // velocity not measured on this device
      continue;
    }
    if (text.empty()) {
      fail(path, line_no,
           column_ref(kColumns[c], h.index[c]) +
               " is empty; only xdot may be left blank (not measured)");
    }
    if (!parse_double(text, v[c])) {
      fail(path, line_no,
           column_ref(kColumns[c], h.index[c]) + ": cannot parse '" + std::string(text) +
               "' as a number; write plain numbers with '.' as decimal point (e.g. 1.5e-3)");
    }
  }
  if (!std::isfinite(v[kT])) {
    fail(path, line_no,
         column_ref("t", h.index[kT]) + ": time '" + std::string(fields[h.index[kT]]) +
             "' is not finite; every row needs a finite time in seconds");
  }
  return v;
}

Trace parse_rows(std::istream& in, const std::string& path, std::size_t& header_line_out) {
  LineReader reader(in);
  const Header h = read_header(reader, path);
  Trace trace;
  trace.voltage_since_column = h.has_since;
  std::size_t previous_line = 0;
  std::vector<std::string_view> fields;
  std::string_view line;
  while (reader.next(line)) {
    const std::size_t line_no = reader.line_no();
    split(line, fields);
    if (fields.size() != h.fields) {
      fail(path, line_no,
           std::to_string(fields.size()) + " fields, but the header (line " +
               std::to_string(h.line) + ") has " + std::to_string(h.fields) +
               "; every row needs one value per header column");
    }
    const auto v = parse_values(fields, h, path, line_no);
    if (!trace.rows.empty() && !(v[kT] > trace.rows.back().t)) {
      fail(path, line_no,
           column_ref("t", h.index[kT]) + ": time " + exact_num(v[kT]) +
               " is not after the previous row's " + exact_num(trace.rows.back().t) + " (line " +
               std::to_string(previous_line) +
               "); rows must be in strictly increasing time order, without duplicates");
    }
    Sample s;
    if (h.has_since) {
      s.voltage_since =
          parse_voltage_since(fields[h.since_index], v[kT], path, line_no, h.since_index);
    }
    if (h.has_current)
      s.current = parse_current(fields[h.current_index], path, line_no, h.current_index);
    s.t = v[kT];
    s.x = v[kX];
    s.xdot = v[kXdot];
    s.temperature = v[kTemp];
    s.voltage = v[kV];
    trace.rows.push_back(s);
    previous_line = line_no;
  }
  header_line_out = h.line;
  return trace;
}

}  // namespace

Trace load_trace(const std::string& path) {
  std::size_t header_line = 0;
  Trace trace = load_rows(path, header_line);
  require_two_rows(trace, path, header_line);
  finish(trace);
  trace.files = {path};
  return trace;
}

Trace load_traces(const std::vector<std::string>& paths) {
  std::vector<std::string> files;
  for (const auto& path : paths) {
    if (std::filesystem::is_directory(path)) {
      for (auto& f : csv_files_in(path)) files.push_back(std::move(f));
    } else {
      files.push_back(path);
    }
  }
  if (files.empty()) throw TraceError("no trace file given");
  if (files.size() == 1) return load_trace(files.front());
  Trace all;
  std::string last_with_rows;
  for (const auto& file : files) {
    std::size_t header_line = 0;
    Trace part = load_rows(file, header_line);
    all.voltage_since_column = all.voltage_since_column || part.voltage_since_column;
    if (part.rows.empty()) {
      all.files.push_back(file);  // a header only: the daemon stopped right after a rotation
      continue;
    }
    if (!all.rows.empty() && !(part.rows.front().t > all.rows.back().t)) {
      throw TraceError(file + ": the first row's time " + exact_num(part.rows.front().t) +
                       " is not after the last time " + exact_num(all.rows.back().t) + " of " +
                       last_with_rows +
                       "; give the files in time order (a rotated recording's names sort so), "
                       "each file of one run once");
    }
    all.rows.insert(all.rows.end(), part.rows.begin(), part.rows.end());
    all.files.push_back(file);
    last_with_rows = file;
  }
  if (all.rows.size() < 2) {
    throw TraceError(
        files.front() + " .. " + files.back() + ": only " + std::to_string(all.rows.size()) +
        " data row(s) in these files; at least 2 are needed to know the sample period");
  }
  finish(all);
  return all;
}

}  // namespace scp::drivers::replay
